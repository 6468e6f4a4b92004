"""The H1 estimate a model is judged against, with the averaging of its points taken
out as far as the model is concerned (:func:`ehss.live.compensate.seen_alike`)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal

import ehss
from ehss.live.compensate import seen_alike
from ehss.validation import frf_error

FS = 1000.0
BAND = (0.5, 20.0)


def _loop(gain: float = 1.0) -> ehss.ArmaxModel:
    """A 10 Hz, zeta 0.42 loop behind 17 samples of delay, unit gain at 0 Hz."""
    w = 2 * np.pi * 10.0
    b, a = scipy.signal.cont2discrete(([w * w], [1.0, 2 * 0.42 * w, w * w]), 1.0 / FS,
                                      method="zoh")[:2]
    b = np.atleast_1d(np.squeeze(b))
    b = np.trim_zeros(b, "f")
    return ehss.ArmaxModel(a=a, b=gain * b, delay=17, dt=1.0 / FS)


def _record(model: ehss.ArmaxModel, n: int, history: int = 0, seed: int = 5):
    """A 0.5-20 Hz drive and the loop's output on it, ``history`` samples run before the
    window (the loop is not at rest when the window begins)."""
    u = ehss.signals.band_limited_random(band_hz=BAND, rms=1.0, duration_s=(n + history) / FS,
                                         fs=FS, seed=seed).values
    return u[history:], model.simulate(u)[history:]


def test_a_model_of_the_loop_agrees_with_the_estimate_at_the_band_edge():
    loop = _loop()
    u, y = _record(loop, 750, history=2000)
    h1 = ehss.h1_estimate(u, y, fs=FS, nperseg=256, delay="auto")
    raw = frf_error(loop, h1, band_hz=BAND, min_coherence=0.0)
    alike = frf_error(loop, seen_alike(loop, h1, u, 0), band_hz=BAND, min_coherence=0.0)
    # the point at 19.5 Hz averages the response over 15.6-23.4 Hz, where the drive
    # stops at 20 Hz, and segments of 256 samples leak the loop's response: the exact
    # model is 14 deg / 1.6 dB off the estimate (a bias: no noise here)
    assert np.max(np.abs(raw.phase_error_deg)) > 10.0
    assert np.max(np.abs(raw.magnitude_error_db)) > 1.0
    # the model's own output seen through the same segments shows the same bias. What
    # is left is the loop's state at the window's start, which the model run from rest
    # does not have: its free response, in the first of the five segments (0.3 deg /
    # 0.04 dB here; up to 1.5 deg / 0.11 dB on other references); without it, nothing
    # is left (the next test). At most a tenth of the bias:
    assert np.max(np.abs(alike.phase_error_deg)) < 0.1 * np.max(np.abs(raw.phase_error_deg))
    assert np.max(np.abs(alike.magnitude_error_db)) \
        < 0.1 * np.max(np.abs(raw.magnitude_error_db))


def test_a_model_of_a_loop_from_rest_is_seen_exactly():
    loop = _loop()
    u, y = _record(loop, 750)
    h1 = seen_alike(loop, ehss.h1_estimate(u, y, fs=FS, nperseg=256, delay="auto"), u, 0)
    err = frf_error(loop, h1, band_hz=BAND, min_coherence=0.0)
    assert np.max(np.abs(err.phase_error_deg)) < 1e-7
    assert np.max(np.abs(err.magnitude_error_db)) < 1e-9


def test_a_model_that_is_off_is_seen_off_by_as_much():
    # the model 5 % above the loop in gain: the estimate compared like with like says
    # so at every point, exactly when both run from rest (y_model = 1.05 y)
    loop, model = _loop(), _loop(1.05)
    u, y = _record(loop, 750)
    h1 = seen_alike(model, ehss.h1_estimate(u, y, fs=FS, nperseg=256, delay="auto"), u, 0)
    err = frf_error(model, h1, band_hz=BAND, min_coherence=0.0)
    np.testing.assert_allclose(err.magnitude_error_db, 20 * np.log10(1.05), rtol=0,
                               atol=1e-9)
    np.testing.assert_allclose(err.phase_error_deg, 0.0, rtol=0, atol=1e-7)


def test_rows_before_a_change_only_run_the_model():
    loop = _loop()
    u, y = _record(loop, 1500)
    whole = seen_alike(loop, ehss.h1_estimate(u[500:], y[500:], fs=FS, nperseg=256), u, 500)
    err = frf_error(loop, whole, band_hz=BAND, min_coherence=0.0)
    assert np.max(np.abs(err.phase_error_deg)) < 1e-6


@pytest.mark.parametrize("pole", [1.01, 1.0])
def test_an_unstable_model_is_left_to_the_guard(pole):
    u, y = _record(_loop(), 750)
    h1 = ehss.h1_estimate(u, y, fs=FS, nperseg=256)
    model = ehss.ArmaxModel(a=[1.0, -pole], b=[0.01], delay=1, dt=1.0 / FS)
    assert seen_alike(model, h1, u, 0) is h1
