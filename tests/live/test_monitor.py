"""The compensation panel's data: tracking RMS per stretch with and without compensation
against the analytic RMS of a sine, the current inverse's response, loads and refusals."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
from numpy.testing import assert_allclose

from ehss.live.dashboard import compensation_columns
from ehss.live.monitor import CompensationMonitor

FS = 100.0


def _sine(n: int) -> np.ndarray:
    # 4 Hz at 100 Hz: a stretch of 0.25 s (25 samples) holds exactly one period
    return np.sin(2 * np.pi * 4.0 * np.arange(n) / FS)


def _feed_in_pieces(mon: CompensationMonitor, d: np.ndarray, fb: np.ndarray,
                    without: np.ndarray | None, cuts: list[int]) -> None:
    for a, b in zip([0, *cuts], [*cuts, d.shape[1]], strict=True):
        mon.feed(d[:, a:b], fb[:, a:b], None if without is None else without[:, a:b])


def test_tracking_rms_per_stretch_is_the_sines_rms():
    d = np.vstack([_sine(100), 2 * _sine(100)])
    mon = CompensationMonitor(("1", "2"), FS, (1.0, 20.0), "preview")
    # pieces that do not fall on the stretches' edges
    _feed_in_pieces(mon, d, 0.9 * d, 0.5 * d, [7, 37, 63])
    snap = mon.snapshot()
    assert snap.mode == "preview" and snap.band_hz == (1.0, 20.0)
    for ch, amp in zip(snap.channels, (1.0, 2.0), strict=True):
        assert_allclose(ch.t, [0.25, 0.5, 0.75, 1.0], rtol=1e-12)
        # RMS of a·sin over whole periods is a/√2 (sums of 25 samples: 1e-12)
        assert_allclose(ch.error_rms, 0.1 * amp / np.sqrt(2), rtol=1e-12)
        assert_allclose(ch.error_rms_without, 0.5 * amp / np.sqrt(2), rtol=1e-12)
        assert ch.inverse is None and ch.loads == 0


def test_a_remote_target_compares_with_its_level_before_the_first_compensator():
    d = _sine(100)[None]
    mon = CompensationMonitor(("1",), FS, (1.0, 20.0), "causal")
    mon.feed(d[:, :50], 0.8 * d[:, :50])          # error 0.2 sin: no compensator yet
    mon.update(0, design=None, loads=1, refusals=0)
    mon.feed(d[:, 50:], 0.95 * d[:, 50:])         # error 0.05 sin with one
    ch = mon.snapshot().channels[0]
    assert_allclose(ch.error_rms, np.array([0.2, 0.2, 0.05, 0.05]) / np.sqrt(2), rtol=1e-12)
    # before the compensator "without" is the error itself, then the level before it
    assert_allclose(ch.error_rms_without, 0.2 / np.sqrt(2), rtol=1e-12)


class _LowPass:
    """A design whose response is 1 / (1 + j f / 10 Hz)."""

    def frequency_response(self, freq_hz):
        return 1.0 / (1.0 + 1j * np.asarray(freq_hz) / 10.0)


def test_the_inverse_response_and_its_columns():
    mon = CompensationMonitor(("1",), FS, (1.0, 100.0), "preview", n_freq=3)
    mon.update(0, design=_LowPass(), loads=2, refusals=1, last_reason="why", model="tracker")
    snap = mon.snapshot()
    ch = snap.channels[0]
    assert_allclose(ch.freq_hz, [1.0, 10.0, 100.0], rtol=1e-12)
    error, inverse = compensation_columns(snap, 0)
    assert error == {"t": [], "with": [], "without": []}
    # at the corner: -10 log10(2) dB and -45 degrees, exactly
    assert_allclose(inverse["mag"][1], -10 * np.log10(2.0), rtol=1e-12)
    assert_allclose(inverse["ph"], np.degrees(-np.arctan([0.1, 1.0, 10.0])), rtol=1e-12)
    assert (ch.loads, ch.refusals, ch.last_reason, ch.model) == (2, 1, "why", "tracker")


def test_follow_counts_each_load_and_refusal_once():
    design = _LowPass()
    log = [SimpleNamespace(accepted=True, reason=""),
           SimpleNamespace(accepted=False, reason="unstable")]
    adapter = SimpleNamespace(name="1", compensator=SimpleNamespace(current=design, log=log))
    loop = SimpleNamespace(adapters=[adapter], loads=[{"channel": "1", "model": "estimator"}])
    mon = CompensationMonitor(("1",), FS, (1.0, 20.0), "preview")
    mon.follow(loop)
    mon.follow(loop)
    log.append(SimpleNamespace(accepted=False, reason="drive too large"))
    loop.loads.append({"channel": "1", "model": "tracker"})
    mon.follow(loop)
    ch = mon.snapshot().channels[0]
    assert (ch.loads, ch.refusals, ch.last_reason, ch.model) == (2, 2, "drive too large",
                                                                 "tracker")
    assert_allclose(ch.inverse, design.frequency_response(ch.freq_hz), rtol=0)
