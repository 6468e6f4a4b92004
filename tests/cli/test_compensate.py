"""``ehss compensate``: files in, drive out; bad input is one line and exit 2, no file."""

from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.signal
from numpy.testing import assert_allclose

from ehss.cli import main
from ehss.io import read_columns, write_csv

DT = 1e-3


def _write_model(path, *, a=(1.0, -1.5, 0.7), b=(0.1, 0.05), delay=2, dt=DT, **extra):
    path.write_text(json.dumps({"a": list(a), "b": list(b), "c": [1.0], "delay": delay,
                                "dt": dt, **extra}))
    return path


def _write_reference(path, r, fs=1 / DT, name="reference"):
    write_csv(path, {"t": np.arange(r.size) / fs, name: r})
    return path


@pytest.fixture
def reference(rng):
    r = scipy.signal.lfilter([0.05], [1, -0.95], rng.standard_normal(1000))
    r[:20] = 0.0
    return r


def test_compensate_writes_drive_that_inverts_the_model(tmp_path, reference):
    model = _write_model(tmp_path / "m.json")
    ref = _write_reference(tmp_path / "r.csv", reference)
    out = tmp_path / "drive.csv"
    assert main(["compensate", str(model), str(ref), "--out", str(out)]) == 0
    table = read_columns(out, ["t", "reference", "drive"])
    assert list(table.columns) == ["t", "reference", "drive"]
    assert_allclose(table["reference"], reference, rtol=0, atol=0)  # repr round trip
    y = scipy.signal.lfilter([0.0, 0.0, 0.1, 0.05], [1.0, -1.5, 0.7], table["drive"])
    # Minimum-phase model (zero at -0.5): exact inverse up to rounding.
    assert_allclose(y, reference, rtol=0, atol=1e-10)


def test_compensate_uses_the_operating_point_of_the_model(tmp_path, reference):
    # identified about (u0, y0) = (2, 1.5): y − y0 = G (u − u0), G(1) = 0.15/0.2 = 0.75
    model = _write_model(tmp_path / "m.json", offsets={"input": 2.0, "output": 1.5})
    r = 1.5 + 0.4 * (np.arange(reference.size) > 100) + reference  # static part and a step
    ref = _write_reference(tmp_path / "r.csv", r)
    out = tmp_path / "drive.csv"
    assert main(["compensate", str(model), str(ref), "--out", str(out)]) == 0
    drive = read_columns(out, ["drive"])["drive"]
    y = 1.5 + scipy.signal.lfilter([0.0, 0.0, 0.1, 0.05], [1.0, -1.5, 0.7], drive - 2.0)
    assert_allclose(y, r, rtol=0, atol=1e-10)
    assert_allclose(drive[:10], 2.0, rtol=0, atol=1e-12)  # at the operating point: u0
    sidecar = json.loads(out.with_suffix(".json").read_text())
    assert sidecar["offsets_applied"] == {"input": 2.0, "output": 1.5}
    # --ignore-offsets: the inverse of the reference as it is (the earlier behaviour)
    out2 = tmp_path / "plain.csv"
    assert main(["compensate", str(model), str(ref), "--out", str(out2),
                 "--ignore-offsets"]) == 0
    plain = read_columns(out2, ["drive"])["drive"]
    from ehss.compensation import compensate
    from ehss.identification.model import ArmaxModel

    assert_allclose(plain, compensate(ArmaxModel.load_json(model), r), rtol=0, atol=1e-12)
    assert np.max(np.abs(plain - drive)) > 0.1  # r's static part starts it off rest
    assert json.loads(out2.with_suffix(".json").read_text())["offsets_applied"] is None


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
    model = _write_model(tmp_path / "m.json", b=(0.1, 0.25))  # zero at -2.5
    ref = _write_reference(tmp_path / "r.csv", reference, name="acc")
    for method in ("zpetc", "zmetc"):
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
        ({"dt": 2e-3}, {}, [], "500 Hz"),
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
    """u+ = u + L F (r − y): with a plant 10 % weaker than the model, the correction after
    one run is exactly L F (r − y) (checked sample by sample), and for L = 1 the next
    run's error is 10 % of the previous one (the plant is the model scaled by 0.9)."""
    model = _write_model(tmp_path / "m.json")
    ref = _write_reference(tmp_path / "r.csv", reference)
    d0 = tmp_path / "d0.csv"
    assert main(["compensate", str(model), str(ref), "--out", str(d0)]) == 0
    u0 = read_columns(d0)["drive"]
    a, b = [1.0, -1.5, 0.7], [0.0, 0.0, 0.1, 0.05]  # delay 2 as leading zeros

    def plant(u):
        return 0.9 * scipy.signal.lfilter(b, a, u)

    y0 = plant(u0)
    run = tmp_path / "run0.csv"
    write_csv(run, {"t": np.arange(u0.size) * DT, "reference": u0, "output": y0})
    d1 = tmp_path / "d1.csv"
    assert main(["compensate", str(model), str(ref), "--update", str(run), "--out",
                 str(d1)]) == 0
    assert "RMS tracking error" in capsys.readouterr().out
    u1 = read_columns(d1)["drive"]
    e0 = reference - y0
    e1 = reference - plant(u1)
    # Linear plant, exact inverse: the error contracts by |1 − 0.9| = 0.1 (rounding only).
    assert_allclose(e1[50:-50], 0.1 * e0[50:-50], rtol=0, atol=1e-9 * np.max(np.abs(e0)))
    side = json.loads(d1.with_suffix(".json").read_text())
    assert side["update"]["gain"] == 1.0


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
