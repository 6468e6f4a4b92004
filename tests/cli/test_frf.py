"""``ehss frf``: CSV columns, every file format, plot, and exit 2 on bad input."""

from __future__ import annotations

import h5py
import numpy as np
import pytest
import scipy.io
import scipy.signal

from ehss.cli import main
from ehss.io import read_columns, write_csv

FS = 1000.0


@pytest.fixture
def record(rng):
    n = 8192
    u = rng.standard_normal(n)
    b, a = scipy.signal.butter(2, 100.0, fs=FS)
    return {"t": np.arange(n) / FS, "u": u, "y": scipy.signal.lfilter(b, a, u)}


def _write(path, record):
    suffix = path.suffix
    if suffix == ".csv":
        write_csv(path, record)
    elif suffix == ".npz":
        np.savez(path, **record)
    elif suffix == ".mat":
        scipy.io.savemat(path, {k: v[:, None] for k, v in record.items()})
    else:
        with h5py.File(path, "w") as fh:
            for k, v in record.items():
                fh[f"run1/{k}"] = v


@pytest.mark.parametrize("suffix", [".csv", ".npz", ".mat", ".h5"])
def test_frf_writes_columns(tmp_path, record, capsys, suffix):
    data = tmp_path / f"run{suffix}"
    _write(data, record)
    cols = ["u", "y"] if suffix != ".h5" else ["run1/u", "run1/y"]
    extra = [] if suffix != ".h5" else ["--time-column", "run1/t"]
    out = tmp_path / "frf.csv"
    code = main(["frf", str(data), "--input", cols[0], "--output", cols[1], *extra,
                 "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    assert "averages" in capsys.readouterr().out
    table = read_columns(out)
    assert list(table) == ["freq_hz", "magnitude_db", "phase_deg", "coherence"]
    f = table["freq_hz"]
    # default: the longest segment with 8 half-overlapping averages of 8192 samples, 1024
    assert f[0] == pytest.approx(FS / 1024)
    h = scipy.signal.freqz(*scipy.signal.butter(2, 100.0, fs=FS), worN=f, fs=FS)[1]
    band = f < 100
    # noise-free: leakage-limited (see tests/test_frequency.py), 0.2 dB in the passband
    np.testing.assert_allclose(table["magnitude_db"][band], 20 * np.log10(np.abs(h[band])),
                               atol=0.2)


def test_frf_nperseg_and_plot(tmp_path, record, capsys):
    data = tmp_path / "run.csv"
    _write(data, record)
    out, plot = tmp_path / "frf.csv", tmp_path / "frf.png"
    assert main(["frf", str(data), "--input", "u", "--output", "y", "--nperseg", "256",
                 "--out", str(out), "--plot", str(plot)]) == 0
    assert read_columns(out)["freq_hz"].size == 128  # 1..128 bins of a 256-point segment
    assert plot.read_bytes()[:4] == b"\x89PNG" and plot.stat().st_size > 20_000


@pytest.mark.parametrize(
    "args,match",
    [
        (["--input", "u", "--output", "y", "--nperseg", "100000"], "longer than the record"),
        (["--input", "u", "--output", "y", "--nperseg", "2"], "--nperseg 2 must be >= 4"),
        (["--input", "nope", "--output", "y"], "no column 'nope'"),
        (["--input", "u", "--output", "y", "--fs", "10"], "--fs is 10 Hz"),
        (["--input", "u", "--output", "u"], "same column"),
        (["--input", "u", "--output", "y", "--band", "20", "10"], "--band 20 10"),
        (["--input", "u", "--output", "y", "--band", "1", "900"], "above fs/2"),
        (["--input", "u", "--output", "y", "--min-coherence", "-1"], "--min-coherence"),
        (["--input", "u", "--output", "y", "--noverlap", "8"], "--method welch"),
        (["--input", "u", "--output", "y", "--method", "welch", "--nperseg", "64",
          "--noverlap", "64"], "noverlap"),
    ],
)
def test_frf_bad_input(tmp_path, record, capsys, args, match):
    data = tmp_path / "run.csv"
    _write(data, record)
    out = tmp_path / "frf.csv"
    code = main(["frf", str(data), *args, "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and match in err, err
    assert not out.exists()


def test_frf_non_finite_and_short(tmp_path, capsys):
    data = tmp_path / "run.csv"
    data.write_text("t,u,y\n" + "".join(f"{k / 1000},{k % 3},{k % 5}\n" for k in range(10)))
    code = main(["frf", str(data), "--input", "u", "--output", "y", "--out",
                 str(tmp_path / "f.csv")])
    err = capsys.readouterr().err
    assert code == 2 and "too few samples" in err
    data.write_text("t,u,y\n0,1,2\n0.001,inf,2\n")
    code = main(["frf", str(data), "--input", "u", "--output", "y", "--out",
                 str(tmp_path / "f.csv")])
    err = capsys.readouterr().err
    assert code == 2 and "non-finite value (inf) at data row 2" in err
    assert not (tmp_path / "f.csv").exists()


def test_outputs_are_plain_csv_with_a_json_sidecar(tmp_path, record):
    """One header row, no comment lines: pandas, MATLAB and spreadsheets open it as is."""
    import json

    data = tmp_path / "rec.csv"
    _write(data, record)
    out = tmp_path / "frf.csv"
    assert main(["frf", str(data), "--input", "u", "--output", "y", "--out", str(out)]) == 0
    first = out.read_text().splitlines()[0]
    assert first == "freq_hz,magnitude_db,phase_deg,coherence"
    table = np.genfromtxt(out, delimiter=",", names=True)
    assert table.dtype.names == ("freq_hz", "magnitude_db", "phase_deg", "coherence")
    side = json.loads(out.with_suffix(".json").read_text())
    assert side["nperseg"] > 0 and "numba" in side["versions"]


def test_frf_defaults_follow_the_record_at_1_hz(tmp_path, rng, capsys):
    # 1000 samples at 1 Hz: not 16-sample segments (a kHz rig's 1 Hz resolution rule) but
    # the longest with 8 averages, 128 samples (14 averages), 64 frequencies
    n = 1000
    u = rng.standard_normal(n)
    y = scipy.signal.lfilter([0.0, 0.5], [1.0, -0.7], u)
    data = tmp_path / "slow.csv"
    write_csv(data, {"u": u, "y": y})
    out = tmp_path / "frf.csv"
    assert main(["frf", str(data), "--input", "u", "--output", "y", "--fs", "1",
                 "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "14 averages of 128 samples" in text
    assert read_columns(out)["freq_hz"].size == 64


def test_frf_dft_estimate_of_a_sweep(tmp_path, rng, capsys):
    # A log sweep 0.5-100 Hz over 16 s, estimated as a sweep analyser does: the whole
    # record's DFT, coherent across the swept band.
    n = 16_384
    t = np.arange(n) / FS
    u = scipy.signal.chirp(t, f0=0.5, t1=t[-1], f1=100.0, method="logarithmic", phi=-90.0)
    u *= scipy.signal.windows.tukey(n, 0.05)
    b, a = scipy.signal.butter(2, 50.0, fs=FS)
    y = scipy.signal.lfilter(b, a, u) + 0.01 * rng.standard_normal(n)
    data = tmp_path / "sweep.csv"
    write_csv(data, {"t": t, "u": u, "y": y})
    out = tmp_path / "frf.csv"
    assert main(["frf", str(data), "--input", "u", "--output", "y", "--band", "0.5", "100",
                 "--method", "dft", "--out", str(out)]) == 0
    assert "whole-record DFT" in capsys.readouterr().out
    table = read_columns(out)
    f = table["freq_hz"]
    inside = (f >= 1.0) & (f <= 70.0)  # away from the sweep's tapered ends
    assert np.all(table["coherence"][inside] >= 0.9)
    h = scipy.signal.freqz(b, a, worN=f[inside], fs=FS)[1]
    # coherence >= 0.98 there with 8 bins averaged: random error of |H| about
    # sqrt(0.02 / 16) ~ 3.5 % (0.3 dB) at the worst point; 0.5 dB is 1.7 of that at the
    # single worst of ~140 points, and the typical point is ten times better.
    np.testing.assert_allclose(table["magnitude_db"][inside], 20 * np.log10(np.abs(h)),
                               atol=0.5)
