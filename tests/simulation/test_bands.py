"""Working bands of Table 2, measured on the nonlinear rig from simulated random tests.

Each loop is driven with a band-limited random reference (seeded), and the closed-loop
frequency response reference → measured output is estimated with H1 (Hann, Welch). The
position and force loops must stay within ±3 dB over 0–20 Hz (judged from 1 Hz, the
lowest frequency a 40 s record resolves well); the acceleration loop cannot meet its
1–50 Hz band with the paper's controller at a 6 dB gain margin (README), so its test
checks the documented figures: within ±3 dB from 1 Hz to about 13 Hz, and the shortfall
at 50 Hz no worse than documented.
"""

from __future__ import annotations

import numpy as np
import pytest

from ehss import preset, signals, simulate
from ehss.frequency import h1_estimate

FS = 1000.0


def _measured_response(loop: str, **size):
    p = preset("default")
    ref = signals.band_limited_random(band_hz=(0.5, 120.0), duration_s=40.0, fs=FS, seed=11,
                                      **size)
    run = simulate(loop, ref, params=p, seed=11)
    u = run.reference - run.reference.mean()
    y = run.output - run.output.mean()
    frf = h1_estimate(u, y, FS, nperseg=2048)
    assert run.limit_fractions["drive_saturated"] == 0.0  # a linear test, not a saturated one
    return frf


def _band_db(frf, lo, hi):
    sel = (frf.freq_hz >= lo) & (frf.freq_hz <= hi)
    # H1 is only trusted where the coherence is high; every point must qualify here.
    assert np.all(frf.coherence[sel] >= 0.95)
    return frf.magnitude_db[sel]


@pytest.mark.slow
@pytest.mark.parametrize(
    ("loop", "size"),
    [("position", {"rms": 1.0e-4}), ("force", {"rms": 200.0})],
)
def test_position_and_force_loops_meet_0_to_20_hz(loop, size):
    frf = _measured_response(loop, **size)
    db = _band_db(frf, 1.0, 20.0)
    assert db.max() <= 3.0 and db.min() >= -3.0


@pytest.mark.slow
def test_acceleration_loop_documented_shortfall():
    frf = _measured_response("acceleration", peak=3.0)
    # The generator's high-pass (ωn = 3.14 rad/s) and the accelerometer coupling take
    # ~1 dB at 1 Hz; the loop holds ±3 dB to about 13 Hz (README, linear design figures).
    assert np.all(np.abs(_band_db(frf, 1.0, 12.0)) <= 3.0)
    at_50 = _band_db(frf, 48.0, 52.0)
    # Documented: about −9.6 dB between 30 and 50 Hz on the sampled linear model; the
    # nonlinear rig must agree within 1.5 dB (noise, valve flow nonlinearity).
    assert np.all(np.abs(at_50 - (-9.6)) <= 1.5)
