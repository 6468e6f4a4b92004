"""Change detection on the simulated rig: a payload step is flagged fast, on its channel
only; stationary running raises nothing (the other loops: test_detect_loops.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ehss.live import (
    DetectionSettings,
    EstimatorSettings,
    LiveSession,
    PacedSource,
    parse_event,
    read_recording,
    rig_record,
)


def _run(layout, x, fs, tmp_path=None, det=None):
    src = PacedSource(layout, x, fs, speed=math.inf)
    record = None if tmp_path is None else tmp_path / "run.h5"
    session = LiveSession(src, est=EstimatorSettings(),
                          det=DetectionSettings() if det is None else det, record=record)
    return session.run()


def test_payload_step_flagged_within_one_second_on_its_channel(tmp_path):
    # +40 % payload (250 → 350 kg) on channel 2 of 3 at t = 20 s
    layout, x, fs = rig_record("position", n_channels=3, duration_s=24.0, seed=11,
                               events=(parse_event("20:mass_kg=350@2"),))
    report = _run(layout, x, fs, tmp_path)
    alarms = [a for a in report.alarms if a["kind"] == "alarm"]
    assert [a["channel"] for a in alarms] == ["2"]
    assert 20.0 < alarms[0]["t_s"] <= 21.0
    # the test decided; the figures an engineer reads come with the alarm
    assert alarms[0]["exceeded"] == ["test"]
    assert all(math.isfinite(alarms[0][k]) for k in ("frf_db", "gain_db", "test"))
    rec = read_recording(tmp_path / "run.h5")
    assert [e["channel"] for e in rec["events"] if e["kind"] == "alarm"] == ["2"]
    np.testing.assert_array_equal(rec["samples"], x)


@pytest.mark.slow
def test_ten_minutes_stationary_with_sensor_noise_raise_no_alarm(tmp_path):
    # the default rig has LVDT noise (2 µm) and 16-bit quantisation; 600 s at 1 kHz,
    # processed faster than real time; the test is set for one false alarm per 24 h,
    # so 10 minutes raise one with probability 1 − e^{−10/1440} = 0.7 %
    layout, x, fs = rig_record("position", n_channels=1, duration_s=600.0, seed=5)
    report = _run(layout, x, fs, tmp_path)
    assert report.samples == x.shape[0]
    assert report.alarms == []
    rec = read_recording(tmp_path / "run.h5")
    assert rec["settings"]["detection"]["false_alarm_hours"] == 24.0
    # the recorded test figure (S/h) is the one the detector judged: evaluated from the
    # end of the learning time on, below 1 throughout
    test = rec["figures"][:, 0, 3]
    assert np.isfinite(test[rec["t"] > 10.5]).all() and np.nanmax(test) < 1.0


def test_compare_recent_flags_the_step_then_clears():
    # against the loop of 3 s ago, a step is a change; once it has lasted 3 s the
    # channel learns the loop anew (5 s), and the alarm clears when the test restarts
    layout, x, fs = rig_record("position", n_channels=1, duration_s=30.0, seed=11,
                               events=(parse_event("15:mass_kg=350"),))
    det = DetectionSettings(compare="recent", recent_s=3.0, learn_s=5.0, clear_s=1.0)
    session = LiveSession(PacedSource(layout, x, fs, speed=math.inf),
                          est=EstimatorSettings(), det=det)
    kinds = [(a["kind"], a["t_s"]) for a in session.run().alarms]
    assert [k for k, _ in kinds] == ["alarm", "clear"]
    assert 15.0 < kinds[0][1] <= 16.0
    # alarm + recent_s + learn_s, or the evaluation after (0.1 s) when samples came
    # between the capture and the evaluation that began the learning
    assert kinds[1][1] == pytest.approx(kinds[0][1] + 8.0 + 0.05, abs=0.06)
    texts = [e["text"] for e in session.events if e["kind"] == "message"]
    assert sum("learning it anew" in t for t in texts) == 1
    assert sum("detection started" in t for t in texts) == 2


def test_given_baseline_model_is_the_start_and_the_reference(tmp_path):
    # a baseline identified offline (same structure) on the rig's own stationary record
    import ehss

    layout, x, fs = rig_record("position", n_channels=1, duration_s=8.0, seed=21,
                               events=(parse_event("5:mass_kg=350"),))
    pre = rig_record("position", n_channels=1, duration_s=10.0, seed=22)[1]
    base = ehss.rels(pre[:, 1], pre[:, 2], na=4, nb=3, nc=4, delay=1, dt=1 / fs, p0=1e3,
                     method="rml")
    det = DetectionSettings(learn_s=1.0)
    session = LiveSession(PacedSource(layout, x, fs, speed=math.inf),
                          est=EstimatorSettings(), det=det, baselines={"1": base})
    report = session.run()
    assert [(a["kind"], a["channel"]) for a in report.alarms] == [("alarm", "1")]
    assert 5.0 < report.alarms[0]["t_s"] <= 6.0
    proc = session.channels[0]
    assert proc.baseline is base
