"""``ehss identify``: files written, model recovered, every bad input is exit 2."""

from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.signal

from ehss.cli import main
from ehss.identification.model import ArmaxModel
from ehss.io import write_csv

FS = 1000.0
TRUE = {"a": [1.0, -1.5, 0.7], "b": [0.1, 0.1], "c": [1.0, 0.3]}


def _record(rng, n=6000, offset=0.5, sigma_e=0.005):
    m = ArmaxModel(**TRUE, delay=1, dt=1 / FS)
    u = rng.standard_normal(n)
    y = m.simulate(u) + scipy.signal.lfilter(m.c, m.a, sigma_e * rng.standard_normal(n))
    return {"t": np.arange(n) / FS, "u": u, "y": y + offset}


@pytest.fixture
def data_csv(tmp_path, rng):
    path = tmp_path / "run.csv"
    write_csv(path, _record(rng))
    return path


ORDERS = ["--na", "2", "--nb", "1", "--nc", "1", "--delay", "1"]


def test_identify_writes_model_and_plots(tmp_path, data_csv, capsys):
    out = tmp_path / "model.json"
    plot = tmp_path / "bode.png"
    code = main(["identify", str(data_csv), "--input", "u", "--output", "y", *ORDERS,
                 "--band", "1", "200", "--out", str(out), "--plot", str(plot)])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "G(z) = (" in captured.out and "pole" in captured.out
    assert "simulation fit" in captured.out
    model = ArmaxModel.load_json(out)
    # 4200 samples, noise 0.005 on outputs of RMS ~1: coefficients to about 1e-2.
    np.testing.assert_allclose(model.a, TRUE["a"], atol=1e-2)
    np.testing.assert_allclose(model.b, TRUE["b"], atol=1e-2)
    doc = json.loads(out.read_text())
    assert doc["offsets"]["output"] == pytest.approx(0.5, abs=0.05)
    assert doc["validation"]["stable"] is True
    assert doc["validation"]["simulation_fit_pct"] > 90
    assert doc["validation"]["frf_error"]["n_points"] > 40  # 1800 held-out samples: 3.9 Hz bins
    prov = doc["provenance"]
    assert prov["input_file"] == str(data_csv) and prov["columns"]["input"] == "u"
    assert prov["settings"]["na"] == 2 and "numpy" in prov["versions"]
    for png in (plot, tmp_path / "bode_time.png"):
        data = png.read_bytes()
        assert data[:4] == b"\x89PNG" and len(data) > 20_000


def test_identify_from_mat_with_fs(tmp_path, rng, capsys):
    import scipy.io

    rec = _record(rng, n=3000)
    path = tmp_path / "run.mat"
    scipy.io.savemat(path, {"ref": rec["u"][:, None], "pos": rec["y"][:, None]})
    out = tmp_path / "m.json"
    assert main(["identify", str(path), "--input", "ref", "--output", "pos", "--fs", "1000",
                 *ORDERS, "--out", str(out)]) == 0
    assert ArmaxModel.load_json(out).dt == pytest.approx(1e-3)


def _bad(tmp_path, capsys, args, match):
    out = tmp_path / "model.json"
    code = main(["identify", *args, "--out", str(out), "--plot", str(tmp_path / "b.png")])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and "Traceback" not in err
    assert match in err, err
    assert not out.exists() and not (tmp_path / "b.png").exists()
    assert not (tmp_path / "b_time.png").exists()


@pytest.mark.parametrize(
    "content,match",
    [
        ("t,u,y\n0,1,2\n0.001,nan,2\n", "non-finite value (nan) at data row 2"),
        ("t,u,y\n0,1,2\n0.001,x,2\n", "column 'u', data row 2: 'x' is not a number"),
        ("t,u,y\n0,1,2\n0.001,1\n", "data row 2 has 2 fields"),
        ("t,u,v\n0,1,2\n0.001,1,2\n", "no column 'y'; available: 't', 'u', 'v'"),
        ("t,u,y\n0,1,2\n0.001,1,3\n0.002,1,3\n0.004,1,4\n0.005,1,4\n",
         "unevenly sampled: the step from data row 3 to row 4"),
        ("", "empty file"),
    ],
)
def test_identify_bad_files(tmp_path, capsys, content, match):
    path = tmp_path / "bad.csv"
    path.write_text(content)
    _bad(tmp_path, capsys, [str(path), "--input", "u", "--output", "y", *ORDERS], match)


def test_identify_missing_and_garbled_files(tmp_path, capsys):
    _bad(tmp_path, capsys, [str(tmp_path / "none.csv"), "--input", "u", "--output", "y",
                            *ORDERS], "no such file")
    junk = tmp_path / "junk.mat"
    junk.write_bytes(b"\x00\xff" * 300)
    _bad(tmp_path, capsys, [str(junk), "--input", "u", "--output", "y", *ORDERS],
         "not a readable MATLAB file")


def test_identify_too_few_samples_for_orders(tmp_path, rng, capsys):
    path = tmp_path / "short.csv"
    write_csv(path, _record(rng, n=40))
    _bad(tmp_path, capsys, [str(path), "--input", "u", "--output", "y", "--na", "8", "--nb",
                            "8", "--nc", "8", "--delay", "1"], "too few")


@pytest.mark.parametrize(
    "extra,match",
    [
        (["--holdout", "1.5"], "--holdout 1.5 must be in [0, 1)"),
        (["--holdout", "0"], "--holdout must be > 0"),
        (["--band", "50", "10"], "--band 50 10"),
        (["--band", "10", "900"], "above fs/2"),
        (["--fs", "500"], "--fs is 500 Hz"),
        (["--na", "-1"], "na"),
        (["--forgetting", "1.5"], "forgetting"),
    ],
)
def test_identify_bad_settings(tmp_path, data_csv, capsys, extra, match):
    _bad(tmp_path, capsys, [str(data_csv), "--input", "u", "--output", "y", *ORDERS, *extra],
         match)


def test_identify_no_time_no_fs(tmp_path, rng, capsys):
    path = tmp_path / "nt.csv"
    rec = _record(rng, n=500)
    write_csv(path, {"u": rec["u"], "y": rec["y"]})
    _bad(tmp_path, capsys, [str(path), "--input", "u", "--output", "y", *ORDERS],
         "pass --fs")


def test_identify_unwritable_output(tmp_path, data_csv, capsys):
    code = main(["identify", str(data_csv), "--input", "u", "--output", "y", *ORDERS,
                 "--out", str(tmp_path / "missing" / "m.json")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "does not exist" in err


def test_identify_missing_required_argument(tmp_path, data_csv, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["identify", str(data_csv), "--input", "u", "--output", "y", "--out", "m.json"])
    assert exc.value.code == 2
    assert "--na" in capsys.readouterr().err
