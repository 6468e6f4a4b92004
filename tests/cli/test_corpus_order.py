"""Hostile grids for ``ehss order``, run as users run it: ranges that are empty or
reversed, negative or non-numeric orders, grids too large for the record or for any
record, hold-outs that leave nothing to estimate or validate on, bands above Nyquist or
upside down. Each is one line on stderr and exit 2; no table is written.

The record: 400 samples at 500 Hz of a second-order loop driven by a seeded white input.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal


@pytest.fixture
def record(tmp_path):
    rng = np.random.default_rng(1)
    u = rng.standard_normal(400)
    y = scipy.signal.lfilter([0.0, 0.2, 0.1], [1.0, -1.2, 0.5], u)
    y += 0.01 * rng.standard_normal(u.size)
    rows = "".join(f"{k / 500.0!r},{float(a)!r},{float(b)!r}\n"
                   for k, (a, b) in enumerate(zip(u, y, strict=True)))
    (tmp_path / "r.csv").write_text("t,u,y\n" + rows)
    return tmp_path


SMALL = ["--na", "1-2", "--nb", "1", "--nc", "1"]

GRIDS = {
    "na up to 60 on a short record": (["--na", "1-60"], ("candidates",)),
    "na 1-30 on a short record": (["--na", "1-30", "--nb", "1", "--nc", "1"],
                                  ("parameters", "estimation samples")),
    "na reversed": (["--na", "3-1"], ("--na", "3-1")),
    "na open range": (["--na", "2-"], ("--na",)),
    "na empty list": (["--na", ","], ("--na",)),
    "na empty": (["--na", ""], ("--na",)),
    "nb negative": (["--nb", "-1"], ("--nb",)),
    "nc text": (["--nc", "x"], ("--nc", "'x'")),
    "nc a fraction": (["--nc", "1.5"], ("--nc",)),
    "delay reversed": (["--delay", "5-2"], ("--delay",)),
    "delay negative": (["--delay", "-1"], ("--delay",)),
    "delay range huge": (["--delay", "0-500"], ("candidates",)),
    "delay beyond the record": ([*SMALL, "--delay", "300"], ("300",)),
    "holdout zero": (["--holdout", "0"], ("--holdout",)),
    "holdout one": (["--holdout", "1"], ("--holdout",)),
    "holdout 0.99": ([*SMALL, "--holdout", "0.99"], ("estimation",)),
    "holdout 0.01": ([*SMALL, "--holdout", "0.01"], ("validation",)),
    "holdout nan": ([*SMALL, "--holdout", "nan"], ("--holdout",)),
    "holdout with validate": ([*SMALL, "--holdout", "0.3", "--validate", "r.csv"],
                              ("--holdout",)),
    "band above nyquist": ([*SMALL, "--band", "10", "300"], ("250 Hz",)),
    "band reversed": ([*SMALL, "--band", "50", "10"], ("--band",)),
    "band empty": ([*SMALL, "--band", "10", "10"], ("--band",)),
    "band negative": ([*SMALL, "--band", "-1", "10"], ("--band",)),
    "decimate zero": ([*SMALL, "--decimate", "0"], ("--decimate",)),
    "decimate beyond the record": ([*SMALL, "--decimate", "1000"], ("1000",)),
    "fs against the time column": ([*SMALL, "--fs", "1000"], ("Hz",)),
    "column missing": ([*SMALL, "--input", "v"], ("'v'",)),
}


@pytest.mark.parametrize("case", list(GRIDS))
def test_a_grid_that_means_nothing_is_refused(record, refused, case):
    extra, words = GRIDS[case]
    refused(["order", "r.csv", "--input", "u", "--output", "y", *extra, "--out", "t.csv"],
            record, *words)


@pytest.mark.parametrize("out", ["r.csv", "r.json", "."])
def test_the_table_onto_the_record_is_refused(record, refused, out):
    refused(["order", "r.csv", "--input", "u", "--output", "y", *SMALL, "--out", out],
            record, out)
