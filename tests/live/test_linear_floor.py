"""The hindsight floor of ``linear_floor`` on loops whose answer is known."""

from __future__ import annotations

import numpy as np
import scipy.signal
from linear_floor import fixed_linear_floor, stretch_refit_rms, stretch_rms

import ehss

FS = 1000.0
BAND = (0.5, 20.0)


def _desired() -> np.ndarray:
    return ehss.signals.band_limited_random(band_hz=BAND, rms=1.0, duration_s=40.0, fs=FS,
                                            seed=3, fade_s=0.2).values[None, :]


def _servo(u: np.ndarray) -> np.ndarray:
    # a 12 Hz, zeta 0.5 loop behind two samples of delay: linear
    b, a = scipy.signal.cont2discrete(([(2 * np.pi * 12.0) ** 2],
                                       [1.0, 2 * 0.5 * 2 * np.pi * 12.0,
                                        (2 * np.pi * 12.0) ** 2]), 1.0 / FS)[:2]
    return scipy.signal.lfilter(np.r_[0.0, 0.0, b.ravel()], a, u, axis=1)


def test_a_linear_loop_is_inverted_to_what_its_reference_holds_outside_the_band():
    d = _desired()
    errors = fixed_linear_floor(_servo, d, FS, BAND)
    # uncompensated the loop lags its reference by tens of degrees (~100 % error); the
    # floor of a linear loop is what the inverse does not reach: the reference's
    # content outside 0.25-25 Hz (its band limit's skirt) and the H1 estimate's error,
    # well below 1 % of the reference (measured 0.32 %)
    first, last = (stretch_rms(e, FS, 10.0, 40.0)[0] for e in (errors[0], errors[-1]))
    assert first > 0.3
    assert last < 0.01


def test_a_loop_that_saturates_leaves_a_floor_a_linear_loop_does_not():
    # the same loop behind a drive clipped at 3x the reference's RMS (the inverse's drive
    # peaks beyond it): the clipping's distortion is left, far above the linear floor
    # (measured 6.6 % against 0.32 %)
    d = _desired()
    clipped = fixed_linear_floor(lambda u: _servo(np.clip(u, -3.0, 3.0)), d, FS, BAND)
    linear = fixed_linear_floor(_servo, d, FS, BAND)
    assert stretch_rms(clipped[-1], FS, 10.0, 40.0)[0] \
        > 5.0 * stretch_rms(linear[-1], FS, 10.0, 40.0)[0]


def test_a_stretchs_refit_takes_a_filter_of_the_reference_and_leaves_the_rest():
    # an error made of a filter of the reference within the taps (a gain, a lead of
    # 30 ms, a lag of 50 ms; 5.6x the noise) plus white noise of RMS 0.01: the refit
    # leaves the noise, less the (2 K + 1) / N of its power its 129 coefficients take on
    # 2000 samples by chance (measured 1.03x that); the sample RMS of 2000 samples
    # scatters by 1.6 % (1/sqrt(2 N)): 4 of them
    d = _desired()
    rng = np.random.default_rng(7)
    noise = 0.01 * rng.standard_normal(d.shape)
    e = 0.02 * d + 0.05 * np.roll(d, -30, axis=1) - 0.03 * np.roll(d, 50, axis=1) + noise
    left = stretch_refit_rms(e, d, FS, 20.0, 22.0)[0]
    expected = stretch_rms(noise, FS, 20.0, 22.0)[0] * np.sqrt(1.0 - 129 / 2000)
    assert abs(left / expected - 1.0) < 0.065
    # at the record's ends the reference is zero outside it, and what a filter of the
    # reference leaves is no more than the error itself
    ends = [stretch_refit_rms(e, d, FS, t, t + 2.0)[0] for t in (0.0, 38.0)]
    assert all(0.0 < x <= stretch_rms(e, FS, t, t + 2.0)[0]
               for x, t in zip(ends, (0.0, 38.0), strict=True))
