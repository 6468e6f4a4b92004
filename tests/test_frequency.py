"""H1 estimate and coherence against exact responses of known discrete systems."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal
from numpy.testing import assert_allclose

from ehss.errors import DataError, ParameterError
from ehss.frequency import (
    FrequencyResponse,
    default_nperseg,
    dft_estimate,
    frf_estimate,
    h1_estimate,
    n_segments,
)

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
    frf = h1_estimate(u, y, FS, nperseg=1024)
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
    frf = h1_estimate(u, y, FS, nperseg=1024)
    band = frf.freq_hz <= 200
    expected = -360.0 * frf.freq_hz * 3 / FS
    # Unwrapped phase of a 3-sample delay is a straight line; the segment-edge error of
    # a 3-sample shift is 3/1024 of the power, under 1°.
    assert_allclose(frf.phase_deg[band], expected[band], atol=1.0)
    assert_allclose(frf.magnitude_db[band], 0.0, atol=0.1)


def test_a_delay_taken_out_makes_a_short_record_of_a_delay_exact(rng):
    # y is u 40 samples late; segments of 256 hold only (1 - 40/256) of each other
    u = rng.standard_normal(1000)
    y = np.concatenate([np.zeros(40), u[:-40]])
    plain = h1_estimate(u, y, FS, nperseg=256)
    aligned = h1_estimate(u, y, FS, nperseg=256, delay=40)
    band = plain.freq_hz <= 200
    # unaligned: the coherence falls by about (1 - tau/T)^2 = 0.71
    assert np.median(plain.coherence[band]) < 0.85
    # aligned, the segments of y are those of u: the response is e^{-j w 40} to rounding
    # and the coherence 1, from the 960 samples left (6 averages)
    expected = np.exp(-2j * np.pi * aligned.freq_hz * 40 / FS)
    assert_allclose(aligned.response, expected, rtol=0, atol=1e-12)
    assert_allclose(aligned.coherence, 1.0, rtol=0, atol=1e-12)
    assert aligned.delay_samples == 40 and aligned.n_averages == n_segments(960, 256, 128)
    assert aligned.band(10.0, 100.0).delay_samples == 40


def test_auto_finds_the_lag_of_a_lagging_response(rng):
    # a low-pass 25 samples late: the cross-correlation peaks at 25 plus its own lag
    b, a = scipy.signal.butter(2, 100.0, fs=FS)
    u = rng.standard_normal(2000)
    y = np.concatenate([np.zeros(25), scipy.signal.lfilter(b, a, u)[:-25]])
    frf = h1_estimate(u, y, FS, nperseg=256, delay="auto")
    assert 25 <= frf.delay_samples <= 28      # the filter's own group delay: 2.25 samples
    band = frf.freq_hz <= 150
    exact = _exact(b, a, frf.freq_hz) * np.exp(-2j * np.pi * frf.freq_hz * 25 / FS)
    plain = h1_estimate(u, y, FS, nperseg=256)
    # the estimate is of the same response, and nearer it
    err, err_plain = (np.max(np.abs(f.response[band] - exact[band])) for f in (frf, plain))
    assert err < 0.02 < err_plain
    # no lag: nothing read late
    assert h1_estimate(u, scipy.signal.lfilter(b, a, u), FS, nperseg=256,
                       delay="auto").delay_samples in (1, 2, 3)
    assert h1_estimate(u, 2.0 * u, FS, nperseg=256, delay="auto").delay_samples == 0


def test_bad_delays(rng):
    u = rng.standard_normal(300)
    with pytest.raises(ParameterError, match="'auto'"):
        h1_estimate(u, u, FS, nperseg=256, delay="late")
    with pytest.raises(ParameterError, match="delay"):
        h1_estimate(u, u, FS, nperseg=256, delay=-1)
    with pytest.raises(DataError, match="less than a segment"):
        h1_estimate(u, u, FS, nperseg=256, delay=45)


def test_band_and_columns(rng):
    u = rng.standard_normal(8192)
    frf = h1_estimate(u, 2 * u, FS)
    sub = frf.band(10, 20)
    assert sub.freq_hz.min() >= 10 and sub.freq_hz.max() <= 20
    cols = frf.to_columns()
    assert list(cols) == ["freq_hz", "magnitude_db", "phase_deg", "coherence"]
    assert_allclose(cols["magnitude_db"], 20 * np.log10(2.0), atol=1e-9)  # exact ratio
    assert frf.resolution_hz == pytest.approx(FS / frf.nperseg)
    with pytest.raises(ParameterError, match="lo < hi"):
        frf.band(20, 10)


@pytest.mark.parametrize(
    "n,fs,band,expected",
    [
        # no band: the longest power of two giving >= 8 half-overlapping averages,
        # whatever the sample rate
        (20_000, 1000.0, None, 4096), (20_000, 1.0, None, 4096), (1000, 1.0, None, 128),
        (2_000, 1000.0, None, 256), (100, 1000.0, None, 16), (60, 1.0, None, 8),
        # a band asks for resolution min(lo/2, (hi-lo)/32): 2-100 Hz needs 1 Hz -> 1024
        (20_000, 1000.0, (2.0, 100.0), 1024),
        # 0.5-20 Hz needs 0.25 Hz -> 4096, which 60 s at 1 kHz affords
        (60_000, 1000.0, (0.5, 20.0), 4096),
        # a band finer than the record can resolve keeps the 8 averages
        (1000, 1.0, (0.001, 0.4), 128),
        # 4 kHz, 60 s, 0.2-50 Hz: 0.1 Hz -> 65536 is too long; 8 averages -> 32768
        (240_000, 4000.0, (0.2, 50.0), 32768),
    ],
)
def test_default_nperseg(n, fs, band, expected):
    nperseg = default_nperseg(n, fs, band_hz=band)
    assert nperseg == expected
    assert n_segments(n, nperseg, nperseg // 2) >= 8 or nperseg <= 16


def test_frf_of_a_1000_sample_record_at_1_hz_is_not_16_samples(rng):
    u = rng.standard_normal(1000)
    y = scipy.signal.lfilter([0.0, 0.5], [1.0, -0.7], u)
    frf = h1_estimate(u, y, 1.0)
    assert frf.nperseg == 128 and frf.n_averages == 14


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


# ------------------------------------------------------------------ whole-record DFT


def test_dft_estimate_of_a_sweep_matches_the_exact_response(rng, lowpass):
    b, a = lowpass
    fs = FS
    t = np.arange(60_000) / fs
    # linear sweep 1-200 Hz over 60 s, starting and ending at rest
    u = scipy.signal.chirp(t, f0=1.0, t1=t[-1], f1=200.0, phi=-90.0)
    u *= scipy.signal.windows.tukey(u.size, 0.02)
    y = scipy.signal.lfilter(b, a, u) + 0.01 * rng.standard_normal(u.size)
    frf = dft_estimate(u, y, fs, n_average=16)
    assert frf.method == "dft" and frf.n_averages == 16 and frf.nperseg == 60_000 // 16
    band = (frf.freq_hz >= 5.0) & (frf.freq_hz <= 150.0)
    h = _exact(b, a, frf.freq_hz[band])
    # The input has |U|^2 ~ n / (2 * 199 Hz * 60 s) per bin, the noise 0.01^2 n / 2:
    # SNR per bin ~ 1e4 / 12 ~ 840 and with 16 bins the relative error is about
    # 1 / sqrt(2 * 16 * 840) ~ 0.6 %, plus the sweep's own ripple between bins (none in
    # the ratio). 2 % is three times that.
    assert_allclose(frf.response[band], h, rtol=0, atol=0.02)
    assert np.all(frf.coherence[band] > 0.99)


def test_dft_estimate_of_a_periodic_tone_is_exact():
    # A whole number of periods on the DFT grid. The end taper (Tukey, 10 %) spreads the
    # tone over neighbouring bins, all inside the group, and scales input and output alike;
    # only the image at -f, 2k = 200 bins away, leaks in, at the taper's side-lobe level
    # (a cosine taper's side lobes fall as 1/m^3): about 1e-6 relative, so 1e-5.
    n, k = 4096, 100
    t = np.arange(n)
    u = np.cos(2 * np.pi * k * t / n)
    y = 0.3 * np.cos(2 * np.pi * k * t / n - 1.0)
    frf = dft_estimate(u, y, FS, n_average=4)
    i = (k - 1) // 4  # groups of 4 bins from bin 1: bin k is in group (k - 1) // 4
    assert frf.freq_hz[i] == pytest.approx((4 * i + 2.5) * FS / n)
    assert abs(frf.response[i]) == pytest.approx(0.3, rel=1e-5)
    assert np.angle(frf.response[i]) == pytest.approx(-1.0, abs=1e-5)
    assert frf.coherence[i] == pytest.approx(1.0, abs=1e-10)


def test_auto_keeps_welch_for_random_and_the_better_estimate_for_a_sweep(rng, lowpass):
    b, a = lowpass
    n = 20_000
    u = rng.standard_normal(n)
    y = scipy.signal.lfilter(b, a, u) + 0.05 * rng.standard_normal(n)
    assert frf_estimate(u, y, FS, band_hz=(1.0, 100.0)).method == "welch"
    # a 20 s log sweep 0.05-100 Hz: the low decades pass in a few segments only
    t = np.arange(n) / FS
    u = scipy.signal.chirp(t, f0=0.05, t1=t[-1], f1=100.0, method="logarithmic", phi=-90.0)
    y = scipy.signal.lfilter(b, a, u) + 0.05 * rng.standard_normal(n)
    band = (0.05, 100.0)
    welch = h1_estimate(u, y, FS, band_hz=band)
    dft = dft_estimate(u, y, FS, band_hz=band)
    auto = frf_estimate(u, y, FS, band_hz=band)
    better = dft if dft.covered_decades(band, 0.9) > 1.25 * welch.covered_decades(band, 0.9) \
        else welch
    assert auto.method == better.method
    assert auto.covered_decades(band, 0.9) >= 0.8 * max(welch.covered_decades(band, 0.9),
                                                        dft.covered_decades(band, 0.9))


def test_covered_decades_analytic():
    # points at 1, 2, 3 Hz with 1 Hz resolution, all valid: log10(1.5/0.5) + log10(2.5/1.5)
    # + log10(3.5/2.5) = log10(3.5/0.5) = log10(7)
    frf = FrequencyResponse(freq_hz=np.array([1.0, 2.0, 3.0]), response=np.ones(3, complex),
                            coherence=np.ones(3), n_averages=8, nperseg=10, fs=10.0)
    assert frf.covered_decades((0.0, 5.0), 0.9) == pytest.approx(np.log10(7.0), rel=1e-12)
    assert frf.covered_decades((1.5, 5.0), 0.9) == pytest.approx(np.log10(3.5 / 1.5),
                                                                 rel=1e-12)
    # a point the input did not excite (30 dB down) does not count
    weak = FrequencyResponse(freq_hz=np.array([1.0, 2.0, 3.0]), response=np.ones(3, complex),
                             coherence=np.ones(3), n_averages=8, nperseg=10, fs=10.0,
                             input_power=np.array([1.0, 1e-4, 1.0]))
    assert weak.valid((0.0, 5.0), 0.9).tolist() == [True, False, True]


def test_dft_estimate_bad_arguments(rng):
    u = rng.standard_normal(100)
    with pytest.raises(ParameterError, match="n_average"):
        dft_estimate(u, u, FS, n_average=1)
    with pytest.raises(DataError, match="constant"):
        dft_estimate(np.ones(100), u, FS)
    with pytest.raises(ParameterError, match="method"):
        frf_estimate(u, u, FS, method="h2")


@pytest.mark.parametrize("window", ["no-such-window", 3, None, ("kaiser",), [1.0, 1.0]])
def test_bad_window_is_a_parameter_error(rng, window):
    u = rng.standard_normal(1000)
    with pytest.raises(ParameterError, match="window="):
        h1_estimate(u, u, 100.0, window=window)


def test_named_window_equals_its_samples(rng):
    # a (name, parameter) window is the same estimate whether scipy or ehss samples it
    u = rng.standard_normal(2000)
    y = np.convolve(u, [0.5, 0.3, 0.2])[: u.size]
    a = h1_estimate(u, y, 100.0, window=("tukey", 0.25), nperseg=256)
    f, s_uy = scipy.signal.csd(u, y, fs=100.0, window=("tukey", 0.25), nperseg=256)
    _, s_uu = scipy.signal.welch(u, fs=100.0, window=("tukey", 0.25), nperseg=256)
    # the same Welch sums divided, bin for bin (DC, removed by the detrend, is left out)
    assert_allclose(a.freq_hz, f[1:], rtol=0)
    assert_allclose(a.response, (s_uy / s_uu)[1:], rtol=1e-12)
