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
    assert "simulation fit" in captured.out and "verdict: meets the acceptance" in captured.out
    model = ArmaxModel.load_json(out)
    # 4200 samples, noise 0.005 on outputs of RMS ~1: coefficients to about 1e-2.
    np.testing.assert_allclose(model.a, TRUE["a"], atol=1e-2)
    np.testing.assert_allclose(model.b, TRUE["b"], atol=1e-2)
    doc = json.loads(out.read_text())
    assert doc["offsets"]["output"] == pytest.approx(0.5, abs=0.05)
    assert doc["validation"]["stable"] is True
    assert doc["validation"]["simulation_fit_pct"] > 90
    # 1800 held-out samples: 225-sample segments at least (8 averages), 128 by the band's
    # need of (200 - 1) / 32 = 6.2 Hz resolution: 7.8 Hz points, 25 of them in 1-200 Hz
    assert doc["validation"]["frf_error"]["n_points"] >= 20
    assert doc["verdict"]["accepted"] is True
    assert model.offsets[1] == pytest.approx(0.5, abs=0.05)
    assert model.band_hz[0] >= 1 and model.band_hz[1] <= 200
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
    try:
        code = main(["identify", *args, "--out", str(out), "--plot", str(tmp_path / "b.png")])
    except SystemExit as exc:  # argparse's own checks (choices)
        code = exc.code
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
         "jumps from 0.002 s at data row 3 to 0.004 s at row 4"),
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
        (["--holdout", "1.5"], "--holdout 1.5 must be in (0, 1)"),
        (["--holdout", "0"], "--holdout 0.0 must be in (0, 1)"),
        (["--holdout", "0.3", "--validate", "x.csv"], "either --holdout or --validate"),
        (["--validate", "nowhere.csv"], "no such file"),
        (["--nperseg", "4"], "--nperseg 4 must be an integer in [8, inf)"),
        (["--nperseg", "100000", "--decimate", "none"], "longer than the validation data"),
        (["--detrend", "quadratic"], "invalid choice: 'quadratic'"),
        (["--decimate", "x"], "--decimate 'x' must be auto, none or an integer"),
        (["--decimate", "0"], "--decimate 0 must be"),
        (["--decimate", "8", "--band", "1", "200"], "beyond the anti-alias filter"),
        (["--decimate", "1000"], "leaves fewer than 256"),
        (["--method", "magic"], "invalid choice: 'magic'"),
        (["--frf-method", "h2"], "invalid choice: 'h2'"),
        (["--initial", "warm"], "invalid choice: 'warm'"),
        (["--min-coherence", "2"], "--min-coherence 2.0 must be in [0, 1]"),
        (["--band", "50", "10"], "--band 50 10"),
        (["--band", "10", "900"], "above fs/2"),
        (["--fs", "500"], "--fs is 500 Hz"),
        (["--na", "-1"], "na"),
    ],
)
def test_identify_bad_settings(tmp_path, data_csv, capsys, extra, match):
    _bad(tmp_path, capsys, [str(data_csv), "--input", "u", "--output", "y", *ORDERS, *extra],
         match)


def test_identify_bad_out_suffix(tmp_path, data_csv, capsys):
    code = main(["identify", str(data_csv), "--input", "u", "--output", "y", *ORDERS,
                 "--out", str(tmp_path / "m.txt")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "written as .json or .mat" in err
    assert not (tmp_path / "m.txt").exists()


def test_identify_validation_file_with_other_rate(tmp_path, data_csv, rng, capsys):
    other = tmp_path / "other.csv"
    rec = _record(rng, n=3000)
    rec["t"] = rec["t"] * 2  # 500 Hz
    write_csv(other, rec)
    _bad(tmp_path, capsys, [str(data_csv), "--input", "u", "--output", "y", *ORDERS,
                            "--validate", str(other)], "they must match")


def test_identify_validates_on_a_separate_file_and_detrends_a_drift(tmp_path, rng, capsys):
    est, val = tmp_path / "est.csv", tmp_path / "val.csv"
    rec = _record(rng, n=4000)
    write_csv(est, rec)
    rec_v = _record(rng, n=3000, offset=0.0)
    # the validation run drifts: a linear trend of 0.3 over the record
    rec_v["y"] = rec_v["y"] + np.linspace(0.0, 0.3, rec_v["y"].size)
    write_csv(val, rec_v)
    out = tmp_path / "m.json"
    code = main(["identify", str(est), "--input", "u", "--output", "y", *ORDERS,
                 "--validate", str(val), "--detrend", "linear", "--out", str(out)])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "separate record of 3000 samples" in captured.out
    assert "from the least-squares initial state" in captured.out
    doc = json.loads(out.read_text())
    assert doc["provenance"]["validation_file"] == str(val)
    assert doc["validation"]["n_validation"] == 3000
    # the drift is removed from the validation record: the fit stays as on the held-out
    # end (noise 0.005 on an output of RMS ~1: above 95 %)
    assert doc["validation"]["simulation_fit_pct"] > 95
    assert doc["identification"]["preprocessing"]["detrend"] == "linear"


def test_identify_writes_matlab_variables(tmp_path, data_csv, capsys):
    import scipy.io

    out = tmp_path / "model.mat"
    code = main(["identify", str(data_csv), "--input", "u", "--output", "y", *ORDERS,
                 "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    v = scipy.io.loadmat(out)
    # 4200 samples, noise 0.005 on outputs of RMS ~1: coefficients to about 1e-2.
    np.testing.assert_allclose(v["A"].ravel(), TRUE["a"], atol=1e-2)
    # B in MATLAB's idpoly form: the delay's leading zero, then b0, b1
    np.testing.assert_allclose(v["B"].ravel(), [0.0, *TRUE["b"]], atol=1e-2)
    assert v["B"].ravel()[0] == 0.0 and float(v["nk"].squeeze()) == 1.0
    np.testing.assert_array_equal(v["num"], v["B"])
    np.testing.assert_array_equal(v["den"], v["A"])
    assert v["C"].shape == (1, 2)
    assert float(v["Ts"].squeeze()) == pytest.approx(1e-3)
    assert float(v["y0"].squeeze()) == pytest.approx(0.5, abs=0.05)
    assert v["offsets"].shape == (1, 2) and v["band_hz"].shape == (1, 2)
    doc = json.loads(str(v["ehss_json"].squeeze()))
    assert doc["verdict"]["accepted"] is True


def test_identify_prints_the_workflow_verdict(tmp_path, capsys):
    # The verdict printed by the command is the library's on the same record: a test of
    # the simulated position loop that the report would judge the same way.
    import ehss
    from ehss.workflow import Preparation, identify

    fs = 1000.0
    ref = ehss.signals.band_limited_random(band_hz=(0.5, 40.0), rms=1e-3, duration_s=20.0,
                                           fs=fs, seed=4)
    run = ehss.simulate("position", ref, seed=4)
    path = tmp_path / "rig.csv"
    write_csv(path, {"t": np.arange(run.output.size) / fs, "r": run.reference,
                     "x": run.output})
    res = identify(run.reference, run.output, fs=fs, orders=(4, 3, 4, 1),
                   preparation=Preparation(band_hz=(0.5, 40.0)))
    code = main(["identify", str(path), "--input", "r", "--output", "x", "--na", "4",
                 "--nb", "3", "--nc", "4", "--band", "0.5", "40",
                 "--out", str(tmp_path / "m.json")])
    out = capsys.readouterr().out
    assert code == 0
    assert res.verdict.format() in out
    doc = json.loads((tmp_path / "m.json").read_text())
    assert doc["verdict"]["accepted"] is res.accepted
    np.testing.assert_allclose(doc["a"], res.model.a, rtol=1e-12)


def test_identify_refuses_to_write_an_unstable_model(tmp_path, rng, capsys):
    # An integrating record fitted with ARX(1,0) lands on a pole at or beyond 1 for a
    # random walk whose increments are driven by u: y(k) = 1.02 y(k-1) + u(k-1) grows.
    n = 2000
    u = rng.standard_normal(n)
    y = scipy.signal.lfilter([0.0, 1.0], [1.0, -1.02], u)
    path = tmp_path / "grow.csv"
    write_csv(path, {"t": np.arange(n) / FS, "u": u, "y": y})
    out = tmp_path / "m.json"
    code = main(["identify", str(path), "--input", "u", "--output", "y", "--na", "1",
                 "--nb", "0", "--nc", "0", "--method", "arx", "--decimate", "none",
                 "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 1 and "unstable" in err and "not written" in err
    assert err.count("\n") == 1 and not out.exists()


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


def test_plot_window_follows_the_record(tmp_path, rng, capsys):
    from ehss.cli._identify import plot_window_s

    # 300 validation samples at 1 Hz: the whole 299 s, not a fixed second (one sample)
    assert plot_window_s(300, 1.0) == 299.0
    assert plot_window_s(9000, 1000.0) == pytest.approx(1.999)
    # and the command draws it for a slow record
    n = 1000
    u = rng.standard_normal(n)
    y = scipy.signal.lfilter([0.0, 0.5], [1.0, -0.7], u) + 0.01 * rng.standard_normal(n)
    path = tmp_path / "slow.csv"
    write_csv(path, {"u": u, "y": y})
    plot = tmp_path / "b.png"
    code = main(["identify", str(path), "--input", "u", "--output", "y", "--fs", "1",
                 "--na", "1", "--nb", "0", "--nc", "1", "--out", str(tmp_path / "m.json"),
                 "--plot", str(plot)])
    assert code == 0, capsys.readouterr().err
    assert (tmp_path / "b_time.png").read_bytes()[:4] == b"\x89PNG"


def test_a_decimated_model_says_what_the_given_delay_became(tmp_path, data_csv, capsys):
    out = tmp_path / "model.json"
    code = main(["identify", str(data_csv), "--input", "u", "--output", "y", "--na", "2",
                 "--nb", "1", "--nc", "1", "--delay", "2", "--decimate", "3", "--out",
                 str(out)])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    said = "delay 2 samples at 1000 Hz = 0 samples of the model at 333.333 Hz (rounded down)"
    # in the model's heading and in the preprocessing lines, the same words both times
    assert captured.out.count(said) == 2
    # judged below the anti-alias filter's transition: 0.8 of 166.7 Hz
    assert "judged up to 133.3 Hz" in captured.out
    assert ArmaxModel.load_json(out).band_hz[1] <= 1000.0 / 3 * 0.4
