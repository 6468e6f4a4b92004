"""The default hold of change detection follows the estimator's memory."""

from __future__ import annotations

import json
import math

import pytest

from ehss.cli import main
from ehss.errors import ParameterError
from ehss.live import DetectionSettings, EstimatorSettings
from ehss.live.detect import Detector


@pytest.mark.parametrize(("memory_s", "hold_s"), [
    (0.3, 0.45),           # 1.5 memories
    (2.0, 3.0),
    (0.05, 0.2),           # at least two evaluations at 0.1 s
    (math.inf, 10.0),      # no forgetting: at most the learning time
])
def test_default_hold_is_one_and_a_half_memories(memory_s, hold_s):
    assert DetectionSettings().for_memory(memory_s).hold_s == pytest.approx(hold_s,
                                                                            rel=1e-12)


def test_a_given_hold_is_kept_and_an_unset_one_refused_by_the_detector():
    assert DetectionSettings(hold_s=0.7).for_memory(5.0).hold_s == 0.7
    with pytest.raises(ParameterError, match="hold"):
        Detector(DetectionSettings())


@pytest.mark.parametrize(("kw", "memory_s"), [
    ({"memory_s": 0.5}, 0.5),
    ({"forgetting": 0.998}, 0.5),           # 1 / ((1 − λ) fs) at 1 kHz
    ({"forgetting": 1.0}, math.inf),
])
def test_estimator_memory(kw, memory_s):
    assert EstimatorSettings(**kw).memory(1000.0) == pytest.approx(memory_s, rel=1e-9)


def test_the_report_records_the_hold_used(tmp_path, capsys):
    report = tmp_path / "r.json"
    assert main(["live", "--rig", "position", "--duration", "2", "--speed", "inf",
                 "--memory", "0.5", "--learn", "1", "--quiet", "--report", str(report)]) == 0
    settings = json.loads(report.read_text())["settings"]
    assert settings["estimator"]["memory_s"] == 0.5
    assert settings["detection"]["hold_s"] == pytest.approx(0.75, rel=1e-12)
    assert settings["forgetting"] == pytest.approx(1 - 1 / 500, rel=1e-12)

