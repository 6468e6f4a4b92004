"""End to end: a shortened run of the paper's programme through the command line."""

from __future__ import annotations

import dataclasses
import inspect
import json
import re

import pytest

from ehss.cli import main
from ehss.experiments.loop_identification import check_model, loop_record
from ehss.identification import ArmaxModel
from ehss.io import read_columns
from ehss.workflow import Acceptance, identify

LOOPS = ("position", "acceleration", "force")


@pytest.fixture(scope="module")
def report_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("run") / "report"
    assert main(["reproduce", "--out", str(out), "--duration", "20", "--seed", "3", "--quiet"]) == 0
    return out


@pytest.mark.slow
def test_files_and_json_layout(report_dir):
    for name in ("report.html", "report.md", "models.json", "best_models.json", "summary.json",
                 "fig12_steps.png", "fig13_position.png", "fig14_acceleration.png",
                 "fig15_force.png", "fig16_compensation_position.png",
                 "fig17_compensation_acceleration.png"):
        assert (report_dir / name).is_file(), name
    models = json.loads((report_dir / "models.json").read_text())
    assert sorted(models) == sorted(LOOPS)
    for m in models.values():
        for key in ("a", "b", "c", "delay", "dt"):
            assert key in m
        assert m["a"][0] == 1.0 and m["dt"] == pytest.approx(1e-3)
    best = json.loads((report_dir / "best_models.json").read_text())
    for loop in LOOPS:
        cols = read_columns(report_dir / "data" / f"{loop}.csv")
        assert list(cols)[:3] == ["t", "reference", "output"]
        assert best[loop]["meets_acceptance"] is True
        assert ArmaxModel.from_dict(best[loop]).is_stable()
    summary = json.loads((report_dir / "summary.json").read_text())
    assert summary["settings"]["seed"] == 3
    assert "numba" in summary["versions"] and "params" in summary


@pytest.mark.slow
def test_models_meet_the_acceptance_or_report_the_order_that_does(report_dir):
    summary = json.loads((report_dir / "summary.json").read_text())
    acc = summary["acceptance"]
    # the report judges by the library's one acceptance, and says which
    assert acc == dataclasses.asdict(Acceptance())
    for loop in LOOPS:
        entry = summary["loops"][loop]
        chosen = entry if entry["passes"] else entry.get("passing_order")
        assert chosen is not None, f"{loop}: no order meets the acceptance"
        assert chosen["verdict"] == {"accepted": True, "failed": [], "acceptance": acc}
        assert chosen["frf_error"]["n_points"] >= acc["min_frf_points"]
        beyond = chosen["frf_error_beyond_uncertainty"]
        assert beyond["max_magnitude_db"] <= acc["max_magnitude_db"]
        assert beyond["max_phase_deg"] <= acc["max_phase_deg"]
        assert chosen["holdout_fit_pct"] >= acc["min_fit_pct"]
        assert chosen["model"]["stable"]


def _record(report_dir, loop, summary, fs):
    """The loop's record from data/*.csv, prepared as the programme prepares it."""
    vs = summary["loops"][loop]["validation_settings"]
    cols = read_columns(report_dir / "data" / f"{loop}.csv")
    return loop_record(cols["reference"], cols["output"], fs=fs,
                       band_hz=tuple(vs["band_hz"]), holdout=vs["holdout"])


@pytest.mark.slow
def test_quoted_verdicts_follow_from_the_written_files(report_dir):
    """Judge models.json's models again on data/*.csv: the report's numbers come back."""
    summary = json.loads((report_dir / "summary.json").read_text())
    models = json.loads((report_dir / "models.json").read_text())
    for loop in LOOPS:
        model = ArmaxModel.from_dict(models[loop])
        chk = check_model(_record(report_dir, loop, summary, 1.0 / model.dt), model,
                          label=models[loop]["label"])
        quoted = summary["loops"][loop]
        # The CSV holds every sample at full precision (repr), so the same data and the
        # same computation give the same numbers; 1e-9 leaves room for the model's
        # coefficients passing through JSON text (exact too, as repr).
        assert chk.verdict.summary() == quoted["verdict"]
        assert chk.fit_pct == pytest.approx(quoted["holdout_fit_pct"], rel=1e-9)
        assert chk.error.n_points == quoted["frf_error"]["n_points"]
        assert chk.error.max_magnitude_db == pytest.approx(
            quoted["frf_error"]["max_magnitude_db"], rel=1e-9)


def _criteria(failed):
    """Which criteria failed, without their numbers."""
    return sorted(re.sub(r"-?\d+(\.\d+)?", "#", f) for f in failed)


@pytest.mark.slow
@pytest.mark.parametrize("loop", LOOPS)
def test_report_and_cli_give_the_same_verdict_on_the_same_record(report_dir, tmp_path,
                                                                 capsys, loop):
    """``ehss identify`` on the loop's record with the programme's options and orders."""
    summary = json.loads((report_dir / "summary.json").read_text())
    entry = summary["loops"][loop]
    vs = entry["validation_settings"]
    na, nb, nc, delay = entry["orders"]
    out = tmp_path / "model.json"
    # Where the workflow can start RELS as the paper does (theta = 0, P(0) = 1e6 I, the
    # programme's settings), the CLI fits the report's very model.
    paper_start = "init" in inspect.signature(identify).parameters
    capsys.readouterr()
    code = main(["identify", str(report_dir / "data" / f"{loop}.csv"), "--input", "reference",
                 "--output", "output", "--na", str(na), "--nb", str(nb), "--nc", str(nc),
                 "--delay", str(delay), "--method", "rels", "--holdout", str(vs["holdout"]),
                 "--band", *(repr(f) for f in vs["band_hz"]), "--decimate", "none",
                 "--detrend", "mean", "--out", str(out),
                 *(["--init", "zero"] if paper_start else [])])
    assert code == 0
    printed = capsys.readouterr().out
    cli = json.loads(out.read_text())
    model = ArmaxModel.from_dict(cli)
    assert model.dt == pytest.approx(1e-3, rel=1e-12)  # at the control rate, not decimated

    # 1. The programme's judgement of the CLI's model is the CLI's, exactly: same record,
    # same preparation, same acceptance.
    chk = check_model(_record(report_dir, loop, summary, 1.0 / model.dt), model, label="cli")
    assert chk.verdict.format() in printed
    assert chk.verdict.summary() == cli["verdict"]
    assert chk.fit_pct == pytest.approx(cli["validation"]["band_fit_pct"], rel=1e-12)
    assert chk.raw_fit_pct == pytest.approx(cli["validation"]["simulation_fit_pct"],
                                            rel=1e-12)
    for key, value in chk.error.summary().items():
        assert value == pytest.approx(cli["validation"]["frf_error"][key], rel=1e-12), key

    # 2. The report's verdict on its paper-order RELS model is the CLI's on its RELS model
    # of the same orders: accepted or not, for the same reasons.
    assert entry["verdict"]["accepted"] == cli["verdict"]["accepted"]
    assert _criteria(entry["verdict"]["failed"]) == _criteria(cli["verdict"]["failed"])
    if paper_start:
        # The same model from the same full-precision data: the same numbers (1e-9
        # leaves room only for the sample rate read back from the time column).
        assert cli["verdict"] == entry["verdict"]
        assert cli["validation"]["band_fit_pct"] == pytest.approx(entry["holdout_fit_pct"],
                                                                  rel=1e-9)
    # Otherwise the CLI's RELS starts from the batch estimate, so its model differs and so
    # does its fit (where the structure is biased, on the position loop, by tens of
    # points); part 1 is where the numbers agree.


@pytest.mark.slow
def test_html_is_self_contained_and_shows_every_figure(report_dir):
    html = (report_dir / "report.html").read_text()
    md = (report_dir / "report.md").read_text()
    figures = re.findall(r"!\[[^\]]*\]\(([^)]+\.png)\)", md)
    assert len(figures) == 7
    assert html.count("src='data:image/png;base64,") == len(figures)
    assert "<script" not in html and "http" not in html.split("</style>")[0]
    for loop in LOOPS:
        assert f"{loop.capitalize()} loop" in html


def test_bad_duration_and_unwritable_out(tmp_path, capsys):
    assert main(["reproduce", "--out", str(tmp_path / "r"), "--duration", "1", "--quiet"]) == 2
    assert "duration_s" in capsys.readouterr().err
    f = tmp_path / "file"
    f.write_text("x")
    assert main(["reproduce", "--out", str(f), "--quiet"]) == 2
    assert f.read_text() == "x"


def test_more_jobs_than_strands_start_no_more_processes(tmp_path, capsys, monkeypatch):
    # the programme has two strands: --jobs 64 on a big machine must not start 63
    # workers (each imports numpy, scipy, numba and matplotlib)
    import contextlib

    import ehss.experiments.pool as pool
    from ehss.errors import DataError

    asked = []

    @contextlib.contextmanager
    def recording_pool(jobs):
        asked.append(jobs)
        raise DataError("stopped before the programme")
        yield  # pragma: no cover

    monkeypatch.setattr(pool, "process_pool", recording_pool)
    assert main(["reproduce", "--out", str(tmp_path / "r"), "--jobs", "64", "--quiet"]) == 2
    assert asked == [pool.PROGRAMME_STRANDS] == [2]
    assert "stopped before the programme" in capsys.readouterr().err


@pytest.mark.parametrize("jobs", ["0", "two"])
def test_jobs_must_be_a_count_of_processes(tmp_path, capsys, jobs):
    with pytest.raises(SystemExit) as exc:
        main(["reproduce", "--out", str(tmp_path / "r"), "--jobs", jobs, "--quiet"])
    assert exc.value.code == 2
    assert "--jobs" in capsys.readouterr().err
    assert not (tmp_path / "r").exists()


@pytest.mark.slow
def test_compensation_meets_its_targets(report_dir):
    summary = json.loads((report_dir / "summary.json").read_text())
    for loop in ("position", "acceleration"):
        c = summary["compensation"][loop]
        # Targets of the compensation demonstration: ±1 dB, ±5°, ≥ 10× on random.
        assert c["max_abs_db_with"] <= 1.0
        assert c["max_abs_deg_with"] <= 5.0
        assert c["improvement"]["random"] >= 10.0


@pytest.mark.slow
def test_paper_preset_runs_and_reports_its_failures(tmp_path, capsys):
    """Table 1/3 as printed: loops barely work, models fail; the report still says so."""
    params = tmp_path / "paper.toml"
    assert main(["params", "--preset", "paper", "--save", str(params)]) == 0
    out = tmp_path / "r"
    code = main(["reproduce", "--params", str(params), "--out", str(out), "--duration", "10",
                 "--quiet"])
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["params"]["name"] == "paper"
    assert summary["params"]["load"]["mass_kg"] == 5000.0
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err
    # the printed gains leave the position and force loops unstable on this rig: said
    # before the run, and the position loop's compensation is not demonstrated (a model
    # of a limit cycle is no closed loop to invert) but reported as such
    for loop in ("position", "force"):
        assert f"warning: the {loop} loop is unstable with these gains" in captured.err
    assert "the acceleration loop is unstable" not in captured.err
    assert "unstable" in summary["compensation_skipped"]["position"]
    assert "position" not in summary["compensation"]
    assert "The position loop's compensation is not demonstrated" in (
        out / "report.md").read_text()
    # a warning repeated for many candidate models is one line with its count
    lines = [ln for ln in captured.err.splitlines() if "identified model is unstable" in ln]
    assert len(lines) <= 1


def _random_reference(path, *, rms_m, band_hz, fade_s, duration_s=16.0, fs=1000.0, seed=7):
    """A band-limited random position reference, faded in and out, as a CSV file."""
    import numpy as np

    from ehss.io import write_csv
    from ehss.signals import band_limited_random, with_fade

    r = np.asarray(band_limited_random(band_hz=band_hz, rms=rms_m, duration_s=duration_s,
                                       fs=fs, seed=seed).values)
    r = np.asarray(with_fade(r, fs=fs, fade_in_s=fade_s, fade_out_s=fade_s))
    write_csv(path, {"t": np.arange(r.size) / fs, "reference": r})
    return r


@pytest.mark.slow
def test_the_acceleration_compensation_model_compensates_through_the_cli(report_dir, tmp_path):
    """The complete acceleration model (rest with its known factors), inverted as it is by
    ``ehss compensate``, on a 0.1 g RMS reference inside its validated band."""
    import numpy as np

    from ehss.io import write_csv
    from ehss.signals import band_limited_random

    model = report_dir / "compensation_acceleration.json"
    lo, hi = json.loads(model.read_text())["band_hz"]
    r = np.asarray(band_limited_random(band_hz=(lo + 0.5, hi - 5.0), rms=0.981, duration_s=16,
                                       fs=1000.0, seed=7, fade_s=0.5).values)
    ref = tmp_path / "ref.csv"
    write_csv(ref, {"t": np.arange(r.size) / 1000.0, "reference": r})
    drive = tmp_path / "drive.csv"
    assert main(["compensate", str(model), str(ref), "--out", str(drive), "--loop",
                 "acceleration"]) == 0
    assert main(["simulate", "--loop", "acceleration", "--reference", str(drive), "--column",
                 "drive", "--out", str(tmp_path / "with.csv")]) == 0
    assert main(["simulate", "--loop", "acceleration", "--reference", str(ref),
                 "--out", str(tmp_path / "without.csv")]) == 0
    improvement = _rms_error(tmp_path / "without.csv", r) / _rms_error(tmp_path / "with.csv", r)
    # the report's target for compensation, 10× on a random reference (about 40× measured)
    assert improvement >= 10.0, improvement


def _rms_error(run_csv, r):
    import numpy as np

    y = np.asarray(read_columns(run_csv)["output"])
    return float(np.sqrt(np.mean((y - r) ** 2)))


@pytest.mark.slow
@pytest.mark.parametrize("name", ["models.json", "best_models.json"])
def test_every_written_model_carries_its_validated_band_and_compensates(report_dir, tmp_path,
                                                                        name):
    """The report's models are what ``ehss identify`` writes: the band their validation
    confirmed and their operating point, so ``ehss compensate`` takes them as they are."""
    summary = json.loads((report_dir / "summary.json").read_text())
    models = json.loads((report_dir / name).read_text())
    for loop, entry in models.items():
        lo, hi = summary["loops"][loop]["validation_settings"]["band_hz"]
        band = entry["band_hz"]
        # the validated band lies inside the band the record was validated over
        assert band is not None and lo - 1e-9 <= band[0] < band[1] <= hi + 1e-9, loop
        assert entry["offsets"] is not None
    position = tmp_path / "position.json"
    position.write_text(json.dumps(models["position"]))
    band = models["position"]["band_hz"]
    ref = tmp_path / "ref.csv"
    _random_reference(ref, rms_m=2e-4, band_hz=(band[0] + 1.0, 20.0), fade_s=0.5)
    assert main(["compensate", str(position), str(ref), "--out", str(tmp_path / "d.csv")]) == 0


@pytest.mark.slow
def test_the_reports_compensation_model_compensates_through_the_cli(report_dir, tmp_path):
    """The model the report says to compensate with, on a user's reference of the working
    band from 0.5 Hz, through ``ehss compensate`` then ``ehss simulate``: one shot."""
    entry = json.loads((report_dir / "compensation_models.json").read_text())["position"]
    model = report_dir / "compensation_position.json"
    assert json.loads(model.read_text()) == entry
    assert entry["meets_acceptance"] is True
    assert entry["band_hz"][0] == 0.0 and entry["band_hz"][1] >= 19.0  # from DC
    assert "compensation_position.json" in (report_dir / "report.md").read_text()
    ref = tmp_path / "ref.csv"
    r = _random_reference(ref, rms_m=5e-4, band_hz=(0.5, 20.0), fade_s=0.5)
    drive = tmp_path / "drive.csv"
    assert main(["compensate", str(model), str(ref), "--out", str(drive)]) == 0
    assert main(["simulate", "--loop", "position", "--reference", str(drive), "--column",
                 "drive", "--out", str(tmp_path / "with.csv")]) == 0
    assert main(["simulate", "--loop", "position", "--reference", str(ref),
                 "--out", str(tmp_path / "without.csv")]) == 0
    improvement = _rms_error(tmp_path / "without.csv", r) / _rms_error(tmp_path / "with.csv", r)
    # What the demonstration reaches one-shot with the same model (about 40×; the
    # uncompensated loop's error is its phase lag, 1/40 of it is the model's residual
    # error and the sensor noise): 30× leaves room for the record's seed, while a model
    # held only to the acceptance (1 dB / 5°) cannot pass 1/|1 - e^{j5°}| ≈ 11×.
    assert improvement >= 30.0, improvement
