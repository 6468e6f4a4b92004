"""ehss live's detection options: a run that never reached detection says so; a baseline
that cannot be a running loop is refused with one line; the rate is recorded."""

from __future__ import annotations

import json

import numpy as np
import pytest

import ehss
from ehss.cli import main


def test_a_record_shorter_than_the_learning_time_says_detection_never_started(
        tmp_path, capsys):
    report = tmp_path / "r.json"
    assert main(["live", "--rig", "position", "--channels", "2", "--duration", "3",
                 "--speed", "inf", "--learn", "10", "--quiet", "--report",
                 str(report)]) == 0
    err = capsys.readouterr().err
    assert "0 alarms" not in err and "no detection" in err
    assert ("ehss live: warning: detection never started on channels 1, 2 (the stream "
            "ended within --learn 10 s)") in err
    assert json.loads(report.read_text())["detection_started"] == {"1": False, "2": False}


def test_the_report_records_the_rate_and_that_detection_ran(tmp_path, capsys):
    report = tmp_path / "r.json"
    assert main(["live", "--rig", "position", "--duration", "8", "--speed", "inf",
                 "--learn", "4", "--false-alarm-hours", "8", "--quiet", "--report",
                 str(report)]) == 0
    err = capsys.readouterr().err
    assert "0 alarms" in err and "never started" not in err
    assert "for one false alarm per 8 h" in err          # the calibration's message
    r = json.loads(report.read_text())
    assert r["settings"]["detection"]["false_alarm_hours"] == 8.0
    assert r["detection_started"] == {"1": True}


def _model(a, b) -> ehss.ArmaxModel:
    return ehss.ArmaxModel(a=np.array(a), b=np.array(b), c=np.array([1.0]), delay=1,
                           dt=1e-3)


@pytest.mark.parametrize(("a", "b", "word"), [
    ([1.0, -2.1, 1.1], [1.0], "is unstable (largest pole radius 1.1 >= 1)"),
    ([1.0, -0.5], [1e300], "has a coefficient of 1e+300"),
])
def test_a_baseline_that_cannot_be_a_running_loop_is_one_line_and_exit_2(
        tmp_path, capsys, a, b, word):
    path = tmp_path / "bad.json"
    _model(a, b).save_json(path)
    assert main(["live", "--rig", "position", "--duration", "2", "--speed", "inf",
                 "--na", "1", "--nb", "0", "--nc", "0", "--baseline", str(path),
                 "--quiet", "--record", str(tmp_path / "run.h5")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and word in err[0] and str(path) in err[0], err
    assert not (tmp_path / "run.h5").exists()


@pytest.mark.parametrize("value", ["0", "-1", "inf", "nan"])
def test_a_bad_rate_is_one_line_and_exit_2(value, capsys):
    assert main(["live", "--rig", "position", "--false-alarm-hours", value,
                 "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "false_alarm_hours" in err[0], err
