"""A model at a decimated rate applied at the record's rate; the drive outside the band."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal

from ehss.compensation import apply_inverse, compensate, design_inverse
from ehss.compensation.rates import rate_factor, to_model_rate, to_record_rate
from ehss.errors import DataError, EhssWarning, ParameterError
from ehss.identification.model import ArmaxModel


def _tones(freqs_hz, amps, fs, n):
    """Tones under a sin² envelope: at rest at both ends, lines at the tones' frequencies."""
    t = np.arange(n) / fs
    env = np.sin(np.pi * np.arange(n) / (n - 1)) ** 2
    return env * sum(a * np.sin(2 * np.pi * f * t) for f, a in zip(freqs_hz, amps, strict=True))


def test_rate_factor():
    assert rate_factor(4096.0, 17 / 4096.0) == 17
    assert rate_factor(1000.0, 1e-3) == 1
    with pytest.raises(DataError, match="2500 Hz but the model at 1000 Hz"):
        rate_factor(2500.0, 1e-3)
    with pytest.raises(DataError, match="500 Hz but the model at 1000 Hz"):
        rate_factor(500.0, 1e-3)  # the model is faster than the reference


@pytest.mark.parametrize("q", [2, 17, 68])
def test_round_trip_in_band(q):
    # Tones up to 0.8 of the model's Nyquist frequency come back unchanged. The filter's
    # pass-band ripple (Kaiser β = 10 over ±32 model samples) is ~1e-5; 1e-4 leaves room
    # for the envelope's own sidebands near the band edge.
    fs, n = 1000.0 * q, 400 * q
    f_nyq = fs / (2 * q)
    x = _tones([0.01 * f_nyq, 0.3 * f_nyq, 0.8 * f_nyq], [1.0, 0.5, 0.25], fs, n)
    xm = to_model_rate(x, q)
    assert xm.size == -(-n // q)
    # sample j of the model-rate signal is at the time of x[j q]
    np.testing.assert_allclose(xm, x[::q], rtol=0, atol=1e-4)
    np.testing.assert_allclose(to_record_rate(xm, q, n), x, rtol=0, atol=1e-4)


def test_round_trip_removes_what_the_model_cannot_see():
    q, fs, n = 8, 8000.0, 16000
    above = _tones([0.7 * fs / 2], [1.0], fs, n)  # far above the model's Nyquist (500 Hz)
    assert np.max(np.abs(to_record_rate(to_model_rate(above, q), q, n))) < 1e-4


def _gain_model(gain, dt, band):
    """G = gain (no dynamics, no delay): its inverse is 1/gain exactly."""
    return ArmaxModel(a=[1.0], b=[gain], delay=0, dt=dt, band_hz=band)


def test_decimated_model_drives_the_record_rate():
    # A model at fs/q applied to a reference at fs gives the drive of the same model
    # applied at fs, inside the band (G = 2, so both are r / 2 there).
    q, fs, n = 10, 5000.0, 50000
    r = _tones([3.0, 40.0], [1.0, 0.3], fs, n)
    slow = compensate(_gain_model(2.0, q / fs, (0.0, 100.0)), r, fs=fs)
    fast = compensate(_gain_model(2.0, 1 / fs, (0.0, 100.0)), r, fs=fs)
    # The sin² envelope spreads each tone with sidelobes falling as (f T)^-3: beyond the
    # 100 Hz band edge that is < (60 Hz · 10 s)^-3 ≈ 5e-9 of it, which the drive passes at
    # the reference's gain instead of halving it; hence 1e-7. The slow model adds the
    # resampling filters' ripple, ~1e-5 (test_round_trip_in_band).
    np.testing.assert_allclose(slow, r / 2, rtol=0, atol=1e-4)
    np.testing.assert_allclose(fast, r / 2, rtol=0, atol=1e-7)


def test_outside_the_band_the_drive_is_the_reference():
    # G = 2 validated over 4-50 Hz: the inverse halves the 10 Hz tone; the 0.5 Hz tone
    # (below lo/2, where the band limit is zero) and the 200 Hz tone (beyond the cutoff)
    # pass unchanged, as the loop runs them without compensation.
    fs, n = 1000.0, 40000
    low, mid, high = (_tones([f], [1.0], fs, n) for f in (0.5, 10.0, 200.0))
    r = low + mid + high
    inverse = design_inverse(_gain_model(2.0, 1 / fs, (4.0, 50.0)))
    assert inverse.cutoff_hz is not None and inverse.cutoff_hz < 200.0
    # The tones sit where the taper is exactly 0 or 1. Their sin² envelope (T = 40 s)
    # spreads each with sidelobes falling as (f T)^-3: the 0.5 Hz tone reaches the taper
    # (from 2 Hz) at (1.5 Hz · 40 s)^-3 ≈ 5e-6 of its amplitude; hence 1e-5.
    np.testing.assert_allclose(apply_inverse(inverse, r, fs), low + mid / 2 + high,
                               rtol=0, atol=1e-5)
    np.testing.assert_allclose(apply_inverse(inverse, r, fs, outside_band="zero"), mid / 2,
                               rtol=0, atol=1e-5)
    with pytest.raises(ParameterError, match="outside_band"):
        apply_inverse(inverse, r, fs, outside_band="keep")


def test_update_correction_stays_in_the_band():
    # The learning update's correction is Q-filtered: nothing outside the band, even
    # though the one-shot drive passes the reference there.
    from ehss.compensation import UpdateOptions, update_drive

    fs, n = 1000.0, 40000
    r = _tones([0.5, 10.0], [1.0, 1.0], fs, n)
    model = _gain_model(2.0, 1 / fs, (4.0, 50.0))
    with pytest.warns(EhssWarning, match=r"50 % of the reference's power lies outside"):
        u = compensate(model, r, fs=fs)                # the 0.5 Hz tone is passed through
    y = 2.0 * scipy.signal.lfilter([0.9], [1.0], u)  # the loop: 10 % less than modelled
    step = update_drive(r, u, y, fs=fs, model=model, options=UpdateOptions(gain=1.0))
    correction = step.drive - u
    # r - y at 0.5 Hz is -0.8 (the pass-through tone, doubled by the loop): left alone
    spec = np.abs(np.fft.rfft(correction))
    f = np.fft.rfftfreq(n, 1 / fs)
    assert spec[np.argmin(np.abs(f - 0.5))] < 1e-6 * spec.max()
    assert spec[np.argmin(np.abs(f - 10.0))] == pytest.approx(spec.max())
