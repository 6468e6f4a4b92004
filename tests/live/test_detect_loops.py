"""With its defaults, change detection holds its false-alarm rate and flags a real
change on loops that are not the simulated rig as well as on the rig: a 25 Hz servo
behind an 80 Hz valve at 2 kHz, a 4 kHz actuator pushing a specimen spring (both linear
state-space models, ``loops_for_detection.py``, 1 % sensor noise, two channels), and
the simulated rig's position loop. Records are processed as fast as the processing
goes (no wall clock): 10 minutes of two channels take seconds."""

from __future__ import annotations

import math

import pytest
from loops_for_detection import servo_record, specimen_record

from ehss.live import (
    DetectionSettings,
    EstimatorSettings,
    LiveSession,
    PacedSource,
    parse_event,
    rig_record,
)


def _servo(duration_s, seed, change_s=None):
    # +40 % moving mass: the 25 Hz mode falls by 1/√1.4 to 21 Hz
    return servo_record(duration_s=duration_s, seed=seed, change_s=change_s,
                        mass_factor=1.4)


def _specimen(duration_s, seed, change_s=None):
    # +40 % specimen stiffness: the oil column's resonance rises from 58 to 63 Hz
    return specimen_record(duration_s=duration_s, seed=seed, change_s=change_s,
                           stiffness_factor=1.4)


def _rig(duration_s, seed, change_s=None):
    # +40 % payload on actuator 1 (250 → 350 kg)
    events = () if change_s is None else (parse_event(f"{change_s}:mass_kg=350@1"),)
    return rig_record("position", n_channels=2, duration_s=duration_s, seed=seed,
                      events=events)


LOOPS = {"servo": _servo, "specimen": _specimen, "rig": _rig}


def _run(record):
    session = LiveSession(PacedSource(*record, speed=math.inf), est=EstimatorSettings(),
                          det=DetectionSettings())
    report = session.run()
    return session, [a for a in report.alarms if a["kind"] == "alarm"]


@pytest.mark.parametrize("seed", [3, 4])
@pytest.mark.parametrize("loop", sorted(LOOPS))
def test_a_forty_percent_change_is_flagged_within_one_and_a_half_seconds(loop, seed):
    # learning 0–10 s, stationary to 20 s, the change on channel 1 at 20 s
    session, alarms = _run(LOOPS[loop](24.0, seed, change_s=20.0))
    assert all(p.detector.started for p in session.channels)
    assert [a["channel"] for a in alarms] == ["1"], alarms
    assert 20.0 < alarms[0]["t_s"] <= 21.5


@pytest.mark.slow
@pytest.mark.parametrize(("loop", "seed"), [("servo", 1), ("servo", 3), ("specimen", 1),
                                            ("rig", 1), ("rig", 3)])
def test_ten_stationary_minutes_raise_no_false_alarm(loop, seed):
    # set for one false alarm per channel per 24 h: two channels for 10 minutes raise
    # one with probability 1 − e^{−2·10/1440} = 1.4 % if the calibration is right, and
    # far more often if it is wrong (the former fixed limits, 0.5 dB and 1 dB held
    # 0.45 s, raised 1 false alarm in 40 channel-minutes on this servo and 15 on this
    # specimen; a test on the blocks' mean square instead of their median, whose upper
    # tail is heavy, crossed 0.96 of its threshold within 10 minutes on the rig).
    # Channel k of seed s is seeded s + k: seeds 1 and 3 share no channel record
    session, alarms = _run(LOOPS[loop](600.0, seed))
    assert all(p.detector.started for p in session.channels)
    assert alarms == []
    for p in session.channels:
        # the test's statistic over its threshold stayed below 1 (its peak is recorded)
        assert 0.0 < p.peak_figures[3] < 1.0
