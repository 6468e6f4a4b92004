"""With its defaults, change detection holds its false-alarm rate and flags a real
change on loops that are not the simulated rig as well as on the rig: a 25 Hz servo
behind an 80 Hz valve at 2 kHz, a 4 kHz actuator pushing a specimen spring (both linear
state-space models, ``loops_for_detection.py``, 1 % sensor noise, two channels), and
the simulated rig's position loop; a loop behind a 0.5 Hz high-pass, a 12 Hz loop
behind 2 ms of delay and a 15 Hz loop with a lightly damped 40 Hz oil-column mode are
flagged too.
Records are processed as fast as the processing
goes (no wall clock): 10 minutes of two channels take seconds."""

from __future__ import annotations

import math

import numpy as np
import pytest
from loops_for_detection import (
    DELAYED,
    HIGH_PASS,
    OIL_COLUMN,
    loop_record,
    servo_record,
    specimen_record,
)

from ehss.live import (
    Block,
    DetectionSettings,
    EstimatorSettings,
    LiveSession,
    PacedSource,
    parse_event,
    rig_record,
)
from ehss.live.source import new_counters


def _servo(duration_s, seed, change_s=None):
    # +40 % moving mass: the 25 Hz mode falls by 1/√1.4 to 21 Hz
    return servo_record(duration_s=duration_s, seed=seed, change_s=change_s,
                        mass_factor=1.4)


def _specimen(duration_s, seed, change_s=None):
    # +40 % specimen stiffness: the oil column's resonance rises from 58 to 63 Hz
    return specimen_record(duration_s=duration_s, seed=seed, change_s=change_s,
                           stiffness_factor=1.4)


def _high_pass(duration_s, seed, change_s=None):
    # +40 % moving mass behind the 0.5 Hz high-pass: the 30 Hz mode falls to 25 Hz
    # (10 stationary minutes on seeds 1 and 3 raised no alarm either; README)
    return loop_record(HIGH_PASS, duration_s=duration_s, seed=seed, change_s=change_s,
                       factor=1.4)


def _delayed(duration_s, seed, change_s=None):
    # +40 % moving mass of the 12 Hz loop behind 2 ms of delay: the mode falls to 10 Hz
    # (10 stationary minutes on seeds 1 and 3 raised no alarm either, the test's
    # statistic at most 0.44 of its threshold)
    return loop_record(DELAYED, duration_s=duration_s, seed=seed, change_s=change_s,
                       factor=1.4)


def _oil_column(duration_s, seed, change_s=None):
    # +40 % mass of the 15 Hz loop with its 40 Hz oil-column mode (ζ 0.15): the modes
    # fall to 12.7 and 33.8 Hz. The baseline's one-step prediction errors alone rose
    # 1-2 standard deviations and flagged it 0.6-5.4 s after it on seeds 1-9; the
    # output errors of its refitted B/A rise 15-23 (README, "Two predictors, one rate")
    return loop_record(OIL_COLUMN, duration_s=duration_s, seed=seed, change_s=change_s,
                       factor=1.4)


def _rig(duration_s, seed, change_s=None):
    # +40 % payload on actuator 1 (250 → 350 kg)
    events = () if change_s is None else (parse_event(f"{change_s}:mass_kg=350@1"),)
    return rig_record("position", n_channels=2, duration_s=duration_s, seed=seed,
                      events=events)


LOOPS = {"servo": _servo, "specimen": _specimen, "high-pass": _high_pass,
         "delayed": _delayed, "oil-column": _oil_column, "rig": _rig}


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
                                            ("oil-column", 1), ("rig", 1), ("rig", 3)])
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


class _LossySource:
    """A record with stretches of samples lost, as a lossy network delivers it: blocks
    of up to 20 consecutive samples, the index jumping over each lost stretch."""

    def __init__(self, layout, x, fs, lost_s):
        self.layout, self.fs, self.counters = layout, fs, new_counters()
        keep = np.ones(x.shape[0], dtype=bool)
        for a, b in lost_s:
            keep[int(a * fs):int(b * fs)] = False
        self._idx, self._x, self._k = np.flatnonzero(keep), x, 0

    @property
    def finished(self) -> bool:
        return self._k >= self._idx.size

    def poll(self, timeout_s):
        out = []
        while not self.finished and len(out) < 100:
            j = self._k
            while (j + 1 < self._idx.size and self._idx[j + 1] == self._idx[j] + 1
                   and j + 1 - self._k < 20):
                j += 1
            i = int(self._idx[self._k])
            out.append(Block(i, self._x[i:int(self._idx[j]) + 1], 0.0))
            self._k = j + 1
        return out

    def close(self) -> None:
        self._k = self._idx.size


def test_lost_samples_raise_no_alarm():
    # twelve losses of 10–65 ms after the learning time: the stream jumps, the
    # baseline's prediction errors see a transient over a few tens of ms, which the
    # blocks' median (of 200 samples) passes over (their mean square does not: a test
    # on it alarmed on both channels at the first loss)
    layout, x, fs = _servo(40.0, 5)
    lost = [(12 + 2.013 * k, 12 + 2.013 * k + 0.01 + 0.005 * k) for k in range(12)]
    session = LiveSession(_LossySource(layout, x, fs, lost), est=EstimatorSettings(),
                          det=DetectionSettings())
    report = session.run()
    assert all(p.detector.started for p in session.channels)
    assert report.alarms == []
    assert report.samples < x.shape[0] - int(0.4 * fs)      # the losses happened


def test_the_second_predictor_joins_at_its_block_however_long_its_refit_takes(monkeypatch):
    # the refit runs on a thread of its own: one held back 0.5 s (past the 2 s of
    # stream it has, which this run processes in a fraction of that) is waited for at
    # its block, and the run is the same to the last bit as with the refit at full speed
    import time

    import ehss.live.channel as channel

    record = _oil_column(24.0, 3, change_s=20.0)
    quick, quick_alarms = _run(record)
    refit = channel.output_error_predictor

    def slow(*args):
        time.sleep(0.5)
        return refit(*args)

    monkeypatch.setattr(channel, "output_error_predictor", slow)
    held, held_alarms = _run(record)
    assert [len(p.residuals) for p in held.channels] == [2, 2]
    assert [(a["channel"], a["t_s"]) for a in held_alarms] == \
        [(a["channel"], a["t_s"]) for a in quick_alarms] and held_alarms
    for p, q in zip(held.channels, quick.channels, strict=True):
        assert np.array_equal(p.peak_figures, q.peak_figures)
    texts = [[(e["t_s"], e["channel"], e["text"]) for e in s.events
              if e["kind"] == "message"] for s in (held, quick)]
    assert texts[0] == texts[1]
    joined = [t for t in texts[0] if "also watches the output errors" in t[2]]
    assert [c for _, c, _ in joined] == ["1", "2"]
    # the two refits share one thread and take turns: the second channel's test
    # started before the first's predictor joined, and its own joins a turn after that
    started = [t for t, _, text in texts[0] if text.startswith("detection started")]
    assert len(started) == 2 and started[1] < joined[0][0]
    assert joined[0][0] == pytest.approx(started[0] + channel.SECOND_PREDICTOR_AFTER_S)
    assert joined[1][0] == pytest.approx(joined[0][0] + channel.SECOND_PREDICTOR_AFTER_S)


def test_a_refit_that_fails_leaves_the_first_predictor_testing_alone(monkeypatch):
    # the refit cannot take its record: a message says so, and the baseline's
    # prediction errors go on alone (the servo's change is flagged by them as well)
    import ehss.live.channel as channel

    def fails(*args):
        raise np.linalg.LinAlgError("singular matrix")

    monkeypatch.setattr(channel, "output_error_predictor", fails)
    session, alarms = _run(_servo(24.0, 3, change_s=20.0))
    assert [len(p.residuals) for p in session.channels] == [1, 1]
    texts = [e["text"] for e in session.events if e["kind"] == "message"]
    assert sum("alone: the refit of its B/A failed (singular matrix)" in t
               for t in texts) == 2
    assert [a["channel"] for a in alarms] == ["1"] and 20.0 < alarms[0]["t_s"] <= 21.5
