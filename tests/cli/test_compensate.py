"""``ehss compensate``: files in, drive out; bad input is one line and exit 2, no file."""

from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.signal
from numpy.testing import assert_allclose

from ehss._files import SIDECAR_KEY
from ehss.cli import main
from ehss.compensation.rates import to_model_rate
from ehss.io import read_columns, write_csv

DT = 1e-3
BAND = [0.0, 100.0]


def _write_model(path, *, a=(1.0, -1.5, 0.7), b=(0.1, 0.05), delay=2, dt=DT, band=BAND,
                 **extra):
    path.write_text(json.dumps({"a": list(a), "b": list(b), "c": [1.0], "delay": delay,
                                "dt": dt, "band_hz": band, **extra}))
    return path


def _write_reference(path, r, fs=1 / DT, name="reference"):
    write_csv(path, {"t": np.arange(r.size) / fs, name: r})
    return path


def _plant(u, gain=1.0):
    """The file model q^-2 (0.1 + 0.05 q^-1)/(1 - 1.5 q^-1 + 0.7 q^-2), from rest."""
    return gain * scipy.signal.lfilter([0.0, 0.0, 0.1, 0.05], [1.0, -1.5, 0.7], u)


@pytest.fixture
def reference():
    # Tones at 5-31 Hz under a Gaussian envelope: at rest at both ends (1e-30) and in the
    # model's 0-100 Hz band to rounding, so the band limit is unity on it.
    t = np.arange(2000) * DT
    tones = np.sin(2 * np.pi * 5 * t) + 0.5 * np.sin(2 * np.pi * 13 * t + 1.0) + 0.3 * np.sin(
        2 * np.pi * 31 * t + 2.0)
    return 0.01 * tones * np.exp(-(((t - 1.0) / 0.2) ** 2))


def test_compensate_writes_drive_that_inverts_the_model(tmp_path, reference):
    model = _write_model(tmp_path / "m.json")
    ref = _write_reference(tmp_path / "r.csv", reference)
    out = tmp_path / "drive.csv"
    assert main(["compensate", str(model), str(ref), "--out", str(out)]) == 0
    table = read_columns(out, ["t", "reference", "drive"])
    assert list(table.columns) == ["t", "reference", "drive"]
    assert_allclose(table["reference"], reference, rtol=0, atol=0)  # repr round trip
    # Stable inversion in the model's band: exact up to rounding (FFT band limit, short
    # recursions; measured ~1e-17 on a peak of 0.01).
    assert_allclose(_plant(table["drive"]), reference, rtol=0, atol=1e-12)
    side = json.loads(out.with_suffix(".json").read_text())
    assert side["method"] == "stable" and side["band_hz"] == BAND
    assert side["band_from"] == "model band_hz"
    assert side["checks"]["figures"]["rms_gain"] < 3.0


def test_model_at_a_decimated_rate_drives_the_reference_rate(tmp_path, reference):
    # The file model at 500 Hz (a record decimated by 2) and a 1 kHz reference whose tones
    # (5-31 Hz) lie far below the model's Nyquist frequency: the drive, at 1 kHz, brought
    # to 500 Hz and run through the model gives the reference's 500 Hz samples. Tolerance:
    # the resampling filters' round trip (~1e-5 of the 0.01 peak, test_rates.py).
    model = _write_model(tmp_path / "m.json", dt=2 * DT)
    ref = _write_reference(tmp_path / "r.csv", reference)
    out = tmp_path / "drive.csv"
    assert main(["compensate", str(model), str(ref), "--out", str(out)]) == 0
    drive = read_columns(out, ["drive"])["drive"]
    assert drive.size == reference.size
    assert_allclose(_plant(to_model_rate(drive, 2)), reference[::2], rtol=0, atol=1e-6)
    side = json.loads(out.with_suffix(".json").read_text())
    assert side["model_fs_hz"] == pytest.approx(500.0) and "fs/2" in side["resampled"]


def test_compensate_uses_the_operating_point_of_the_model(tmp_path, reference):
    # identified about (u0, y0) = (2, 1.5): y − y0 = G (u − u0), G(1) = 0.15/0.2 = 0.75
    model = _write_model(tmp_path / "m.json", offsets={"input": 2.0, "output": 1.5})
    r = 1.5 + reference  # at rest about the operating point
    ref = _write_reference(tmp_path / "r.csv", r)
    out = tmp_path / "drive.csv"
    assert main(["compensate", str(model), str(ref), "--out", str(out)]) == 0
    drive = read_columns(out, ["drive"])["drive"]
    assert_allclose(1.5 + _plant(drive - 2.0), r, rtol=0, atol=1e-12)
    assert_allclose(drive[:10], 2.0, rtol=0, atol=1e-12)  # at the operating point: u0
    sidecar = json.loads(out.with_suffix(".json").read_text())
    assert sidecar["offsets_applied"] == {"input": 2.0, "output": 1.5}


def test_reference_not_at_rest_needs_a_fade(tmp_path, reference, capsys):
    model = _write_model(tmp_path / "m.json")
    ref = _write_reference(tmp_path / "r.csv", 0.005 + reference)
    out = tmp_path / "drive.csv"
    assert main(["compensate", str(model), str(ref), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "starts at 0.005" in err and "--fade" in err and not out.exists()
    assert main(["compensate", str(model), str(ref), "--out", str(out), "--fade", "0.2"]) == 0
    table = read_columns(out, ["reference", "drive"])
    assert table["reference"][0] == 0.0
    # the band limit's ringing of the faded start, not a jump
    assert abs(table["drive"][0]) < 1e-3 * np.max(np.abs(table["drive"]))
    assert json.loads(out.with_suffix(".json").read_text())["fade_s"] == 0.2


def test_model_without_a_band_needs_one(tmp_path, reference, capsys):
    model = _write_model(tmp_path / "m.json", band=None)
    ref = _write_reference(tmp_path / "r.csv", reference)
    out = tmp_path / "drive.csv"
    assert main(["compensate", str(model), str(ref), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "carries no validated band" in err and "--band" in err and "\n" not in err
    assert not out.exists()
    assert main(["compensate", str(model), str(ref), "--out", str(out), "--band", "0",
                 "100"]) == 0
    assert json.loads(out.with_suffix(".json").read_text())["band_from"] == "--band"


def test_drive_far_beyond_the_reference_is_refused(tmp_path, reference, capsys):
    # A loop with gain 0.15 in the band: the exact drive is ~6× the reference.
    model = _write_model(tmp_path / "m.json", b=(0.02, 0.01))
    ref = _write_reference(tmp_path / "r.csv", reference)
    out = tmp_path / "drive.csv"
    assert main(["compensate", str(model), str(ref), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "× the reference's (bound 3×)" in err and "nothing written" in err
    assert not out.exists() and not out.with_suffix(".json").exists()
    assert main(["compensate", str(model), str(ref), "--out", str(out), "--max-gain",
                 "10"]) == 0
    out2 = tmp_path / "forced.csv"
    assert main(["compensate", str(model), str(ref), "--out", str(out2), "--force"]) == 0
    assert json.loads(out2.with_suffix(".json").read_text())["checks"]["forced"] is True


def test_drive_breaking_the_rig_limits_is_refused(tmp_path, capsys):
    # A position drive whose inverse needs 0.5 m/s where the rig allows 0.2 m/s (Table 2):
    # 20 mm at 4 Hz under an envelope.
    model = _write_model(tmp_path / "m.json")
    t = np.arange(2000) * DT
    r = 0.02 * np.sin(2 * np.pi * 4 * t) * np.exp(-(((t - 1.0) / 0.2) ** 2))
    ref = _write_reference(tmp_path / "r.csv", r)
    out = tmp_path / "drive.csv"
    args = ["compensate", str(model), str(ref), "--out", str(out)]
    assert main([*args, "--loop", "position", "--preset", "default"]) == 2
    err = capsys.readouterr().err
    assert "peak velocity" in err and "0.2 m/s" in err and not out.exists()
    assert main([*args, "--max-velocity", "0.2"]) == 2
    assert "peak rate" in capsys.readouterr().err and not out.exists()
    # --loop alone checks the default preset's limits, as `ehss simulate` does
    assert main([*args, "--loop", "position"]) == 2
    assert "peak velocity" in capsys.readouterr().err and not out.exists()
    assert main([*args, "--max-velocity", "1.0", "--max-stroke", "0.05"]) == 0
    limits = json.loads(out.with_suffix(".json").read_text())["checks"]["limits"]
    assert limits == {"max_abs": 0.05, "max_rate": 1.0, "max_rate2": None}


@pytest.mark.parametrize("flag", ["--max-velocity", "--max-acceleration"])
def test_a_bound_that_is_not_positive_is_named_by_its_flag(tmp_path, reference, capsys, flag):
    model = _write_model(tmp_path / "m.json")
    ref = _write_reference(tmp_path / "r.csv", reference)
    out = tmp_path / "drive.csv"
    assert main(["compensate", str(model), str(ref), "--out", str(out), flag, "-1"]) == 2
    err = capsys.readouterr().err
    assert f"{flag} -1.0 must be in (0, inf)" in err and err.count("\n") == 1
    assert not out.exists()


@pytest.mark.parametrize("offsets", [{"input": 1.0}, {"input": "x", "output": 0.0}, [1, 2],
                                     {"input": float("inf"), "output": 0.0}])
def test_bad_offsets_exit_2(tmp_path, reference, capsys, offsets):
    model = tmp_path / "m.json"
    _write_model(model)
    doc = json.loads(model.read_text())
    doc["offsets"] = offsets
    model.write_text(json.dumps(doc))
    ref = _write_reference(tmp_path / "r.csv", reference)
    out = tmp_path / "drive.csv"
    assert main(["compensate", str(model), str(ref), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "offsets" in err and "\n" not in err
    assert not out.exists()


def test_compensate_options(tmp_path, reference):
    model = _write_model(tmp_path / "m.json", b=(0.1, 0.25))  # zero at -2.5, G(1) = 1.75
    ref = _write_reference(tmp_path / "r.csv", reference, name="acc")
    for method in ("stable", "zpetc", "zmetc"):
        out = tmp_path / f"{method}.csv"
        code = main(["compensate", str(model), str(ref), "--out", str(out), "--column", "acc",
                     "--method", method, "--band", "0", "100"])
        assert code == 0
        assert np.all(np.isfinite(read_columns(out, ["drive"])["drive"]))


@pytest.mark.parametrize(
    ("model_kw", "ref_kw", "extra", "match"),
    [
        ({"a": (1.0, -1.2)}, {}, [], "max pole radius 1.2"),
        ({"b": (0.0, 0.0)}, {}, [], "all zero"),
        ({"dt": 2.5e-3}, {}, [], "400 Hz"),  # not an integer fraction of 1 kHz
        ({}, {"name": "other"}, [], "reference"),
        ({}, {}, ["--fs", "2000"], "2000"),
    ],
)
def test_bad_input_exit_2_one_line_no_output(tmp_path, reference, capsys, model_kw, ref_kw,
                                             extra, match):
    model = _write_model(tmp_path / "m.json", **model_kw)
    ref = _write_reference(tmp_path / "r.csv", reference, **ref_kw)
    out = tmp_path / "drive.csv"
    code = main(["compensate", str(model), str(ref), "--out", str(out), *extra])
    err = capsys.readouterr().err
    assert code == 2
    assert len(err.strip().splitlines()) == 1, err
    assert match in err
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["drive.csv", "m.json", "r.csv"][1:]


def test_non_finite_reference(tmp_path, capsys):
    model = _write_model(tmp_path / "m.json")
    ref = tmp_path / "r.csv"
    ref.write_text("t,reference\n0.0,0.0\n0.001,nan\n")
    out = tmp_path / "drive.csv"
    assert main(["compensate", str(model), str(ref), "--out", str(out)]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
    assert not out.exists()


def test_missing_model_file(tmp_path, reference, capsys):
    ref = _write_reference(tmp_path / "r.csv", reference)
    out = tmp_path / "drive.csv"
    assert main(["compensate", str(tmp_path / "none.json"), str(ref), "--out", str(out)]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert not out.exists()


def test_model_with_known_factors_needs_band_and_inverts_them(tmp_path, capsys):
    # A model identified behind the acceleration loop's known factors (compose): the
    # factors travel in its JSON, and the drive inverts rest and factors.
    from ehss.control.known import known_factors
    from ehss.identification.known import compose
    from ehss.identification.model import ArmaxModel
    from ehss.params import preset

    num, den = known_factors("acceleration", preset("default"))
    rest = ArmaxModel(a=[1.0, -1.5, 0.7], b=[0.1, 0.05], c=[1.0], delay=2, dt=DT)
    path = tmp_path / "m.json"
    compose(rest, num, den).save_json(path)
    t = np.arange(8000) * DT
    r = np.sin(2 * np.pi * 4.0 * t) * np.exp(-(((t - 4.0) / 0.7) ** 2))  # at rest, in band
    ref = _write_reference(tmp_path / "r.csv", r)
    out = tmp_path / "drive.csv"
    assert main(["compensate", str(path), str(ref), "--out", str(out)]) == 2
    assert "band" in capsys.readouterr().err
    assert not out.exists()
    assert main(["compensate", str(path), str(ref), "--out", str(out), "--band", "1",
                 "50"]) == 0
    drive = read_columns(out, ["drive"])["drive"]
    y = scipy.signal.lfilter(num, den, rest.simulate(drive))
    # Exact in band up to rounding near F's roots at z ≈ 0.997 (see test_inverse).
    assert_allclose(y, r, rtol=0, atol=1e-8)


def test_drive_file_iteration_from_a_run(tmp_path, reference, capsys):
    """u+ = u + L F (r − y): with a plant 10 % weaker than the model the default gain is
    1 (|1 − 0.9| = 0.1 contracts), and the next run's error is 10 % of the previous one.
    A run whose error grew is refused: the next drive backs off to half the gain."""
    model = _write_model(tmp_path / "m.json")
    ref = _write_reference(tmp_path / "r.csv", reference)
    d0 = tmp_path / "d0.csv"
    assert main(["compensate", str(model), str(ref), "--out", str(d0)]) == 0
    u0 = read_columns(d0)["drive"]
    y0 = _plant(u0, 0.9)
    run0 = tmp_path / "run0.csv"
    write_csv(run0, {"t": np.arange(u0.size) * DT, "reference": u0, "output": y0})
    d1 = tmp_path / "d1.csv"
    assert main(["compensate", str(model), str(ref), "--update", str(run0), "--previous",
                 str(d0), "--out", str(d1)]) == 0
    assert "run 1: RMS error" in capsys.readouterr().out
    t1 = read_columns(d1)
    u1 = t1["drive"]
    e0, e1 = reference - y0, reference - _plant(u1, 0.9)
    # Linear plant, exact inverse in the band: the error contracts by 0.1 (rounding only).
    assert_allclose(e1, 0.1 * e0, rtol=0, atol=1e-9 * np.max(np.abs(e0)))
    assert_allclose(t1["base_drive"] + t1["correction"], u1, rtol=0, atol=1e-15)
    side = json.loads(d1.with_suffix(".json").read_text())
    assert side["iteration"]["gain"] == 1.0 and len(side["iteration"]["log"]) == 1
    assert side["iteration"]["log"][0]["nrmse_percent"] == pytest.approx(10.0, rel=1e-6)
    # A second run that went wrong (a disturbance doubled the error): refused, halved.
    run1 = tmp_path / "run1.csv"
    write_csv(run1, {"t": np.arange(u1.size) * DT, "reference": u1,
                     "output": reference - 3.0 * e0})
    d2 = tmp_path / "d2.csv"
    assert main(["compensate", str(model), str(ref), "--update", str(run1), "--previous",
                 str(d1), "--out", str(d2)]) == 0
    assert "update refused, gain halved to 0.5" in capsys.readouterr().out
    u2 = read_columns(d2)["drive"]
    assert_allclose(u2, t1["base_drive"] + 0.5 * t1["correction"], rtol=0, atol=1e-15)
    it = json.loads(d2.with_suffix(".json").read_text())["iteration"]
    assert it["halvings"] == 1 and [e["accepted"] for e in it["log"]] == [True, False]
    # The run must have played the previous drive file.
    assert main(["compensate", str(model), str(ref), "--update", str(run0), "--previous",
                 str(d1), "--out", str(tmp_path / "d3.csv")]) == 2
    assert "did not play" in capsys.readouterr().err


@pytest.mark.parametrize("extra", [["--method", "frf"], ["--previous", "d0.csv"],
                                   ["--gain", "0.5"], ["--reidentify"]])
def test_iteration_options_need_a_run(tmp_path, reference, capsys, extra):
    model = _write_model(tmp_path / "m.json")
    ref = _write_reference(tmp_path / "r.csv", reference)
    out = tmp_path / "d.csv"
    assert main(["compensate", str(model), str(ref), "--out", str(out), *extra]) == 2
    err = capsys.readouterr().err
    assert "--update" in err and len(err.strip().splitlines()) == 1 and not out.exists()


def test_drive_file_iteration_rejects_other_rates(tmp_path, reference, capsys):
    model = _write_model(tmp_path / "m.json")
    ref = _write_reference(tmp_path / "r.csv", reference)
    run = tmp_path / "run.csv"
    write_csv(run, {"t": np.arange(reference.size) * 2 * DT, "reference": reference,
                    "output": reference})
    out = tmp_path / "d.csv"
    assert main(["compensate", str(model), str(ref), "--update", str(run), "--out",
                 str(out)]) == 2
    assert "sampled at 500 Hz" in capsys.readouterr().err and not out.exists()


def test_time_column_by_name_and_the_summary_line(tmp_path, reference, capsys):
    model = _write_model(tmp_path / "m.json")
    ref = tmp_path / "r.csv"
    write_csv(ref, {"time_s": np.arange(reference.size) * DT, "ref_m": reference})
    out = tmp_path / "drive.csv"
    args = ["compensate", str(model), str(ref), "--column", "ref_m", "--out", str(out)]
    # no column t: the sample rate is unknown, and the message names both ways to give it
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "--time-column" in err and "--fs" in err and not out.exists()
    assert main([*args, "--time-column", "time_s"]) == 0
    summary = capsys.readouterr().out.strip()
    assert summary.startswith(f"{out}: {reference.size} samples at 1000 Hz, stable inverse "
                              "within 0-100 Hz; drive/reference gain rms")
    side = json.loads(out.with_suffix(".json").read_text())
    assert side["fs_hz"] == pytest.approx(1 / DT)
    assert_allclose(read_columns(out, ["t"])["t"], np.arange(reference.size) * DT)


def test_cli_drive_is_the_librarys(tmp_path, reference):
    """One pipeline: the CLI writes what ``ehss.compensation.compensation`` returns, with
    the operating point, checks and offsets it used."""
    from ehss.compensation import compensation
    from ehss.identification.model import ArmaxModel

    model = _write_model(tmp_path / "m.json", offsets={"input": 2.0, "output": 1.5})
    r = 1.5 + reference
    ref = _write_reference(tmp_path / "r.csv", r)
    out = tmp_path / "drive.csv"
    assert main(["compensate", str(model), str(ref), "--out", str(out)]) == 0
    result = compensation(ArmaxModel.load_json(model), r, fs=1 / DT)
    assert result.offsets == (2.0, 1.5) and result.failed_check is None
    assert_allclose(read_columns(out)["drive"], result.drive, rtol=0, atol=0)
    side = json.loads(out.with_suffix(".json").read_text())
    assert side["checks"]["figures"] == result.check.to_dict()
    assert side["offsets_applied"] == {"input": 2.0, "output": 1.5}


def test_drive_far_below_the_reference_is_refused(tmp_path, reference, capsys):
    # B 100× too large (a unit error): G(1) = 75, the exact drive is ~1/75 of the reference,
    # under the 1/3 bound (checks.py notes: a closed servo loop does not amplify by 10 dB).
    model = _write_model(tmp_path / "m.json", b=(10.0, 5.0))
    ref = _write_reference(tmp_path / "r.csv", reference)
    out = tmp_path / "drive.csv"
    assert main(["compensate", str(model), str(ref), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "× the reference's (bound 0.333×)" in err and "nothing written" in err
    assert err.count("\n") == 1 and not out.exists()
    assert main(["compensate", str(model), str(ref), "--out", str(out), "--min-gain",
                 "0.001"]) == 0


def test_non_finite_drive_is_one_error_type(tmp_path, reference, capsys):
    """A drive that overflows is a ParameterError in the library and exit 2 in the CLI."""
    from ehss.compensation import compensate
    from ehss.errors import ParameterError
    from ehss.identification.model import ArmaxModel

    # b = 1e-310 (subnormal): the exact inverse multiplies by 1e310, beyond float64
    model = _write_model(tmp_path / "m.json", b=(1e-310, 0.0))
    with pytest.raises(ParameterError, match="not finite") as library:
        with np.errstate(over="ignore", invalid="ignore"):
            compensate(ArmaxModel.load_json(model), reference, fs=1 / DT, max_gain=None)
    ref = _write_reference(tmp_path / "r.csv", reference)
    out = tmp_path / "drive.csv"
    with np.errstate(over="ignore", invalid="ignore"):
        assert main(["compensate", str(model), str(ref), "--out", str(out), "--force"]) == 2
    # the CLI's line is the library's error, word for word: the same check raised it
    assert str(library.value) in capsys.readouterr().err and not out.exists()


def test_a_drive_compensate_accepts_for_a_loop_is_one_simulate_plays(tmp_path, capsys):
    """One rig check: a drive within the stroke but beyond the velocity limit is refused by
    both commands with the same figure, and one inside the limits is played."""
    model = _write_model(tmp_path / "m.json")
    t = np.arange(2000) * DT
    ref = _write_reference(tmp_path / "r.csv", 0.02 * np.sin(2 * np.pi * 4 * t) * np.exp(
        -(((t - 1.0) / 0.2) ** 2)))
    out = tmp_path / "drive.csv"
    # without --loop the rig's limits are not checked, and the user is told so
    assert main(["compensate", str(model), str(ref), "--out", str(out)]) == 0
    assert "not checked against a rig's limits" in capsys.readouterr().err
    assert main(["simulate", "--loop", "position", "--reference", str(out), "--column",
                 "drive", "--out", str(tmp_path / "run.csv")]) == 2
    refused_by_simulate = capsys.readouterr().err.strip().split("exceeds")[0].split()[-2]
    out2 = tmp_path / "drive2.csv"
    assert main(["compensate", str(model), str(ref), "--out", str(out2), "--loop",
                 "position"]) == 2
    err = capsys.readouterr().err
    assert f"peak velocity {refused_by_simulate} m/s" in err and not out2.exists()
    small = _write_reference(tmp_path / "small.csv", 0.002 * np.sin(2 * np.pi * 4 * t) * np.exp(
        -(((t - 1.0) / 0.2) ** 2)))
    assert main(["compensate", str(model), str(small), "--out", str(out2), "--loop",
                 "position"]) == 0
    assert main(["simulate", "--loop", "position", "--reference", str(out2), "--column",
                 "drive", "--out", str(tmp_path / "run.csv")]) == 0


def _iteration_files(tmp_path, reference, suffix):
    """A one-shot drive, its run, the first update (written as ``suffix``), its run."""
    model = _write_model(tmp_path / "m.json")
    ref = _write_reference(tmp_path / "r.csv", reference)
    d0 = tmp_path / f"d0{suffix}"
    assert main(["compensate", str(model), str(ref), "--out", str(d0)]) == 0
    u0 = read_columns(d0)["drive"]
    run0 = tmp_path / "run0.csv"
    write_csv(run0, {"t": np.arange(u0.size) * DT, "reference": u0,
                     "output": _plant(u0, 0.9)})
    d1 = tmp_path / f"d1{suffix}"
    assert main(["compensate", str(model), str(ref), "--update", str(run0), "--previous",
                 str(d0), "--out", str(d1)]) == 0
    u1 = read_columns(d1)["drive"]
    run1 = tmp_path / "run1.csv"
    write_csv(run1, {"t": np.arange(u1.size) * DT, "reference": u1,
                     "output": _plant(u1, 0.9)})
    return model, ref, d1, run1


@pytest.mark.parametrize("suffix", [".parquet", ".npz", ".h5"])
def test_previous_drive_in_a_binary_table(tmp_path, reference, capsys, suffix):
    """The iteration record travels inside a binary table: --previous reads it there."""
    model, ref, d1, run1 = _iteration_files(tmp_path, reference, suffix)
    d2 = tmp_path / "d2.csv"
    assert main(["compensate", str(model), str(ref), "--update", str(run1), "--previous",
                 str(d1), "--out", str(d2)]) == 0
    assert len(json.loads(d2.with_suffix(".json").read_text())["iteration"]["log"]) == 2


@pytest.mark.parametrize("edit", [
    lambda d: "a string",
    lambda d: {**d, "iteration": "a string"},
    lambda d: {**d, "iteration": {k: v for k, v in d["iteration"].items() if k != "gain"}},
    lambda d: {**d, "iteration": {k: v for k, v in d["iteration"].items()
                                  if k != "base_rms_error"}},
    lambda d: {**d, "iteration": {**d["iteration"], "gain": -0.5}},
    lambda d: {**d, "iteration": {**d["iteration"], "gain": float("nan")}},
    lambda d: {**d, "iteration": {**d["iteration"], "base_rms_error": "x"}},
    lambda d: {**d, "iteration": {**d["iteration"], "halvings": -1}},
])
def test_edited_previous_sidecar_is_one_line_and_nothing_written(tmp_path, reference, capsys,
                                                                 edit):
    model, ref, d1, run1 = _iteration_files(tmp_path, reference, ".csv")
    side = d1.with_suffix(".json")
    doc = json.loads(side.read_text())
    edited = edit(doc)
    if isinstance(edited, dict):  # still this table's sidecar, so it may be replaced
        edited[SIDECAR_KEY] = doc[SIDECAR_KEY]
    side.write_text(json.dumps(edited))
    capsys.readouterr()
    d2 = tmp_path / "d2.csv"
    assert main(["compensate", str(model), str(ref), "--update", str(run1), "--previous",
                 str(d1), "--out", str(d2)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("ehss compensate: error:") and err.count("\n") == 1
    assert "Traceback" not in err and str(d1) in err
    assert not d2.exists() and not d2.with_suffix(".json").exists()


@pytest.mark.parametrize("command", [
    ["compensate-demo", "--loop", "position", "--seed", "-3"],
    ["simulate", "--loop", "position", "--signal", "sine", "--seed", "-1"],
])
def test_negative_seed_is_one_line(tmp_path, capsys, command):
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as exc:
        main([*command, "--out", str(out if command[0] == "compensate-demo"
                                        else tmp_path / "run.csv")])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "--seed" in err and ">= 0" in err and err.count("\n") == 1
    assert not out.exists() and not (tmp_path / "run.csv").exists()
