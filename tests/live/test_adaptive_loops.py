"""Adaptive compensation with its default settings on loops that are not the simulated
rig (``stepping_loops.py``: two channels, 1 % sensor noise, the band taken from the
reference): the 25 Hz servo at 2 kHz after +40 % moving mass, and the actuator on its
specimen at 4 kHz after +40 % specimen stiffness, on channel 1 at t = 20 s. The figures
asserted and their spread over other references are in the README ("Adaptive
compensation", "On loops that are not the rig")."""

from __future__ import annotations

import math

import numpy as np
import pytest
from stepping_loops import SERVO, SPECIMEN, SteppingLoop, loop_desired

from ehss.live.compensate import AdaptiveLoop, CompensationSettings

CHANGE_S = 20.0
DURATION_S = 30.0
#: Stretches after the change judged one by one: 2 s each, from 2 s after it to the end.
_WINDOWS_S = [(t, t + 2.0) for t in np.arange(CHANGE_S + 2.0, DURATION_S, 2.0)]

#: Each case: the loop, the reference's band (flat, nothing outside; the band the
#: compensation works over is found from it), the factor of the parameter that changes,
#: and the bound of channel 1's error over [22, 24) s against its level before. The
#: servo's change raises its error 20–35× and the correction that follows it leaves
#: 5–8× for about a second, until the first full model's inverse is in (22.0–22.3 s):
#: [22, 24) s measured 1.9–3.1× over six pairs of references; the specimen's 0.85–1.08×.
CASES = {
    "servo 2 kHz, +40 % mass": (SERVO, (1.0, 50.0), 1.4, 4.0),
    "specimen 4 kHz, +40 % stiffness": (SPECIMEN, (1.0, 40.0), 1.4, 1.5),
}


def _run(target: SteppingLoop, adapt_until_s: float = math.inf):
    return AdaptiveLoop(target, CompensationSettings(adapt_until_s=adapt_until_s)).run()


@pytest.mark.slow
@pytest.mark.parametrize("case", list(CASES))
def test_adaptation_follows_a_change_of_another_loop(case):
    spec, ref_band, factor, first_bound = CASES[case]
    desired = loop_desired(spec, DURATION_S, (1, 2), band_hz=ref_band)

    def target() -> SteppingLoop:
        return SteppingLoop(spec, desired, preview=128, seed=0, change_s=CHANGE_S,
                            factor=factor)

    adapted = _run(target())
    frozen = _run(target(), adapt_until_s=CHANGE_S - 0.1)   # the inverse of before
    plain = target().step(desired.shape[1])                  # no compensation
    fs = spec.fs
    err = (plain.desired - plain.feedback)[:, int(10 * fs):int(CHANGE_S * fs)]
    uncompensated = np.sqrt(np.mean(err**2, axis=1))

    before = adapted.tracking_rms(10.0, CHANGE_S)
    # steady state: at least 20 times less error than without compensation (measured
    # 120-127x on the servo, 49-51x on the specimen)
    assert np.all(before <= uncompensated / 20.0)
    # the change is flagged on channel 1 within 0.75 s (0.1-0.2 s measured: the error
    # rises 20-35x on the servo, 4-5x on the specimen), and not on channel 2 after it
    changes = [(e["channel"], e["t_s"]) for e in adapted.events
               if e["kind"] == "compensator_change" and e["t_s"] > CHANGE_S]
    assert changes and changes[0][0] == "1" and changes[0][1] <= CHANGE_S + 0.75
    assert all(c[0] == "1" for c in changes)
    # a change of a healthy loop is followed, not alarmed
    assert not [e for e in adapted.events if e["kind"] == "alarm"]
    after = [adapted.tracking_rms(*w) for w in _WINDOWS_S]
    assert after[0][0] <= first_bound * before[0]
    # from 4 s after the change on, every 2-s stretch within 1.5x the level before
    # (measured up to 1.44x)
    for a in after[1:]:
        assert a[0] <= 1.5 * before[0]
    # the inverse of before the change, not adapted, at least 2x worse in every stretch
    # (measured 9-12x)
    for w, a in zip(_WINDOWS_S, after, strict=True):
        assert frozen.tracking_rms(*w)[0] >= 2.0 * a[0], w
    # channel 2 does not change: within the scatter of 1-s stretches before (+-30 %)
    assert adapted.tracking_rms(CHANGE_S + 2.0, DURATION_S)[1] <= 1.3 * before[1]
    assert adapted.loads and all(load["accepted"] for load in adapted.loads)
