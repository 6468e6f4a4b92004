"""H1 estimate and coherence against exact responses of known discrete systems."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal
from numpy.testing import assert_allclose

from ehss.errors import DataError, ParameterError
from ehss.frequency import FrequencyResponse, default_nperseg, h1_estimate

FS = 1000.0


@pytest.fixture
def lowpass():
    # Second-order Butterworth at 100 Hz: a smooth, known discrete response.
    return scipy.signal.butter(2, 100.0, fs=FS)


def _exact(b, a, freq_hz):
    return scipy.signal.freqz(b, a, worN=freq_hz, fs=FS)[1]


def test_h1_matches_exact_response_noise_free(rng, lowpass):
    b, a = lowpass
    u = rng.standard_normal(40_000)
    y = scipy.signal.lfilter(b, a, u)
    frf = h1_estimate(u, y, FS)
    assert frf.nperseg == 1024 and frf.n_averages == 77
    assert frf.freq_hz[0] == pytest.approx(FS / 1024)  # 0 Hz left out after detrending
    h = _exact(b, a, frf.freq_hz)
    band = frf.freq_hz <= 150.0
    # Without noise the only error is the segment-edge leakage of the impulse response
    # (about 10 samples long against 1024-sample segments): about 1 % of |H|.
    assert_allclose(frf.response[band], h[band], rtol=0, atol=0.02)
    assert np.all(frf.coherence[band] > 0.99)


def test_h1_unbiased_with_output_noise(rng, lowpass):
    b, a = lowpass
    n = 60_000
    u = rng.standard_normal(n)
    clean = scipy.signal.lfilter(b, a, u)
    sigma_n = 0.3
    y = clean + sigma_n * rng.standard_normal(n)
    frf = h1_estimate(u, y, FS, nperseg=512)
    h = _exact(b, a, frf.freq_hz)
    band = frf.freq_hz <= 80.0
    # Coherence of a linear system with white output noise: |H|^2 / (|H|^2 + σn²/σu²).
    gamma2 = np.abs(h) ** 2 / (np.abs(h) ** 2 + sigma_n**2)
    # The coherence estimate has a standard deviation of about
    # sqrt(2) γ² (1 − γ²) / sqrt(n_d) (Bendat & Piersol 9.81) plus leakage; allow 5σ.
    sd = np.sqrt(2) * gamma2 * (1 - gamma2) / np.sqrt(frf.n_averages)
    assert np.all(np.abs(frf.coherence[band] - gamma2[band]) <= 5 * sd[band] + 0.01)
    assert np.all(frf.coherence[band] < 0.99)
    # Random error of |H1| relative: sqrt(1 − γ²) / (γ sqrt(2 n_d)) (Bendat & Piersol
    # 9.90); the phase error has the same size in radians, so the complex error
    # |H1 − H| / |H| has RMS sqrt(1 − γ²) / (γ sqrt(n_d)). Hann segments overlapping by
    # half are not independent (variance about 1.1× that of n_d independent ones), so
    # the RMS normalised error over the ~40 points must be near 1: within 0.7–1.35.
    err = np.abs(frf.response - h) / np.abs(h)
    sigma = np.sqrt(1 - gamma2) / np.sqrt(gamma2 * frf.n_averages)
    z = (err / sigma)[band]
    assert 0.7 < np.sqrt(np.mean(z**2)) < 1.35
    assert z.max() < 4.0


@pytest.mark.parametrize("gain,phase_deg", [(2.5, -60.0), (0.1, 135.0), (1.0, 0.0)])
def test_sine_gives_exact_gain_and_phase(gain, phase_deg):
    nperseg = 1000
    k = 50  # on a frequency bin: f = k fs / nperseg = 50 Hz
    f0 = k * FS / nperseg
    t = np.arange(20_000) / FS
    u = np.sin(2 * np.pi * f0 * t)
    y = gain * np.sin(2 * np.pi * f0 * t + np.radians(phase_deg))
    frf = h1_estimate(u, y, FS, nperseg=nperseg)
    i = int(np.argmin(np.abs(frf.freq_hz - f0)))
    assert frf.freq_hz[i] == pytest.approx(f0, rel=1e-12)
    # On a bin a Hann window leaks only into the neighbouring bins, and the -f0 image
    # is 2k bins away: the ratio is exact to rounding.
    assert abs(frf.response[i]) == pytest.approx(gain, rel=1e-9)
    assert np.degrees(np.angle(frf.response[i])) == pytest.approx(phase_deg, abs=1e-7)
    assert frf.coherence[i] == pytest.approx(1.0, abs=1e-9)


def test_pure_delay_phase(rng):
    u = rng.standard_normal(30_000)
    y = np.concatenate([np.zeros(3), u[:-3]])
    frf = h1_estimate(u, y, FS)
    band = frf.freq_hz <= 200
    expected = -360.0 * frf.freq_hz * 3 / FS
    # Unwrapped phase of a 3-sample delay is a straight line; the segment-edge error of
    # a 3-sample shift is 3/1024 of the power, under 1°.
    assert_allclose(frf.phase_deg[band], expected[band], atol=1.0)
    assert_allclose(frf.magnitude_db[band], 0.0, atol=0.1)


def test_band_and_columns(rng):
    u = rng.standard_normal(8192)
    frf = h1_estimate(u, 2 * u, FS)
    sub = frf.band(10, 20)
    assert sub.freq_hz.min() >= 10 and sub.freq_hz.max() <= 20
    cols = frf.to_columns()
    assert list(cols) == ["freq_hz", "magnitude_db", "phase_deg", "coherence"]
    assert_allclose(cols["magnitude_db"], 20 * np.log10(2.0), atol=1e-9)  # exact ratio
    assert frf.resolution_hz == pytest.approx(FS / frf.nperseg)
    with pytest.raises(ParameterError, match="lo <= hi"):
        frf.band(20, 10)


@pytest.mark.parametrize(
    "n,fs,expected", [(20_000, 1000.0, 1024), (2_000, 1000.0, 256), (100, 1000.0, 16),
                      (200_000, 4096.0, 4096)]
)
def test_default_nperseg(n, fs, expected):
    assert default_nperseg(n, fs) == expected


def test_bad_arguments(rng):
    u = rng.standard_normal(100)
    with pytest.raises(DataError, match="same length"):
        h1_estimate(u, u[:-1], FS)
    with pytest.raises(DataError, match=r"u\[4\]=nan is not finite"):
        h1_estimate(np.where(np.arange(100) == 4, np.nan, u), u, FS)
    with pytest.raises(DataError, match="too few samples"):
        h1_estimate(u[:10], u[:10], FS)
    with pytest.raises(DataError, match="constant"):
        h1_estimate(np.ones(100), u, FS)
    with pytest.raises(ParameterError, match="fs"):
        h1_estimate(u, u, -1.0)
    with pytest.raises(DataError, match="longer than the record"):
        h1_estimate(u, u, FS, nperseg=128)
    with pytest.raises(ParameterError, match="noverlap"):
        h1_estimate(u, u, FS, nperseg=32, noverlap=32)
    with pytest.raises(ParameterError, match="detrend"):
        h1_estimate(u, u, FS, detrend="quadratic")
    with pytest.raises(DataError, match="1-D"):
        h1_estimate(u.reshape(10, 10), u.reshape(10, 10), FS)
    with pytest.raises(ParameterError, match="same shape"):
        FrequencyResponse(freq_hz=np.zeros(3), response=np.zeros(2), coherence=np.zeros(3),
                          n_averages=1, nperseg=4, fs=1.0)
