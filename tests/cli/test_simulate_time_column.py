"""`ehss simulate --reference FILE` takes the file's time column, in its stated unit."""

from __future__ import annotations

import json

import numpy as np
import pytest

from ehss.cli import main
from ehss.io import read_columns


@pytest.mark.parametrize(("name", "scale"), [("time [ms]", 1e3), ("t", 1.0)])
def test_the_rate_comes_from_the_named_time_column(tmp_path, name, scale):
    fs, n = 500.0, 1000
    k = np.arange(n)
    r = 1e-3 * np.sin(2 * np.pi * 2 * k / fs) * np.sin(np.pi * k / (n - 1)) ** 2
    ref = tmp_path / "ref.csv"
    np.savetxt(ref, np.c_[np.arange(n) / fs * scale, r], delimiter=",",
               header=f"{name},reference", comments="")
    out = tmp_path / "run.csv"
    args = ["simulate", "--loop", "position", "--reference", str(ref), "--out", str(out)]
    assert main(args + (["--time-column", name] if name != "t" else [])) == 0
    t = read_columns(out, ["t"])["t"]
    # the run is at the file's 500 Hz: the record's own time column says so
    assert t.size == n and t[1] - t[0] == pytest.approx(1 / fs, rel=1e-9)
    meta = json.loads(out.with_suffix(".json").read_text())
    assert json.dumps(meta).count(name) >= 1
