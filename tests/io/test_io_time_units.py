"""A time column whose name states its unit ("t [ms]") is read in that unit."""

from __future__ import annotations

import numpy as np
import pytest

from ehss.cli import main
from ehss.errors import DataError
from ehss.io import read_columns, sample_rate
from ehss.io.readers import time_unit


@pytest.mark.parametrize(("name", "seconds"), [
    ("t", 1.0), ("time", 1.0), ("time_s", 1.0), ("Time (s)", 1.0), ("timestamp", 1.0),
    ("t [ms]", 1e-3), ("time (ms)", 1e-3), ("time_ms", 1e-3), ("t ms", 1e-3),
    ("t/ms", 1e-3), ("Time [us]", 1e-6), ("t [µs]", 1e-6), ("t_ns", 1e-9),
    ("t [min]", 60.0), ("t2", 1.0),
])
def test_the_unit_a_name_states(name, seconds):
    assert time_unit(name)[1] == seconds


def test_a_unit_that_is_not_of_time_is_refused():
    with pytest.raises(DataError, match="'samples', not a unit of time.*--fs"):
        time_unit("t [samples]")


def _record(path, time_name, scale, fs=200.0, n=4000):
    rng = np.random.default_rng(3)
    u = rng.standard_normal(n)
    y = np.convolve(u, [0.0, 0.5, 0.25])[:n]
    t = np.arange(n) / fs * scale
    with open(path, "w", encoding="utf-8-sig", newline="\r\n") as f:
        f.write(f"{time_name};ref [mm];pos [mm]\n")
        for row in zip(t, u, y, strict=True):
            f.write(";".join(repr(float(v)) for v in row) + "\n")


@pytest.mark.parametrize(("time_name", "scale"), [("t [ms]", 1e3), ("time_us", 1e6),
                                                  ("t [s]", 1.0)])
def test_the_sample_rate_comes_out_in_hertz(tmp_path, time_name, scale):
    path = tmp_path / "rec.csv"
    _record(path, time_name, scale)
    table = read_columns(path, ["ref [mm]", "pos [mm]"], time_column=time_name)
    # the steps are k / 200 · scale, exact to a few ulps of the largest time: the rate
    # from the span is 200 Hz to ~1e-12
    assert sample_rate(table) == pytest.approx(200.0, rel=1e-12)
    assert table.time[-1] == pytest.approx(3999 / 200.0, rel=1e-12)


def test_the_command_line_reads_milliseconds(tmp_path, capsys):
    # before, "t [ms]" was taken as seconds: a 0.2 Hz record, a band up to 0.1 Hz
    path = tmp_path / "rec.csv"
    _record(path, "t [ms]", 1e3)
    out = tmp_path / "frf.csv"
    assert main(["frf", str(path), "--input", "ref [mm]", "--output", "pos [mm]",
                 "--time-column", "t [ms]", "--out", str(out)]) == 0
    assert "..100 Hz" in capsys.readouterr().out
    f = read_columns(out, ["freq_hz"], time_column=None)["freq_hz"]
    assert f.max() == pytest.approx(100.0, rel=1e-12)       # fs / 2 at 200 Hz


def test_without_a_time_column_the_message_names_the_likely_one(tmp_path):
    path = tmp_path / "rec.csv"
    _record(path, "time_s", 1.0)
    table = read_columns(path, None)
    with pytest.raises(DataError, match=r"--time-column COL or pass --fs HZ "
                                        r"\(the file has 'time_s'\)"):
        sample_rate(table)


def test_a_gap_in_the_time_stamps_is_named_as_missing_samples(tmp_path):
    # jittered stamps (1 % of the step) and, further on, two samples dropped: the gap is
    # what the message names, with the rows around it
    fs, n = 1000.0, 3000
    t = np.arange(n) / fs + np.random.default_rng(4).normal(0.0, 1e-5, n)
    t = np.delete(t, [2000, 2001])
    x = np.zeros(t.size)
    path = tmp_path / "gap.csv"
    np.savetxt(path, np.c_[t, x, x], delimiter=",", header="t,u,y", comments="")
    with pytest.raises(DataError, match=r"data row 2000 .* row 2001, 3.0. typical steps .*"
                                        r"2 sample\(s\) missing there"):
        sample_rate(read_columns(path, ["u", "y"]))


def test_jittered_stamps_point_to_ignoring_them(tmp_path):
    fs, n = 1000.0, 3000
    t = np.arange(n) / fs + np.random.default_rng(4).normal(0.0, 2e-5, n)
    x = np.zeros(n)
    path = tmp_path / "jitter.csv"
    np.savetxt(path, np.c_[t, x, x], delimiter=",", header="t,u,y", comments="")
    with pytest.raises(DataError, match=r"unevenly sampled.*pass --fs HZ with "
                                        r"--time-column '' to ignore them"):
        sample_rate(read_columns(path, ["u", "y"]))
    # and that is what the command line then accepts
    assert sample_rate(read_columns(path, ["u", "y"], time_column=None), fs) == fs
