"""Detrending and decimation against analytic answers."""

from __future__ import annotations

import hypothesis.extra.numpy as hnp
import hypothesis.strategies as st
import numpy as np
import pytest
import scipy.signal
from hypothesis import given, settings
from numpy.testing import assert_allclose

from ehss.errors import DataError, ParameterError
from ehss.preprocess import auto_decimation, content_edge_hz, decimate, detrend


def test_detrend_mean_and_line_are_exact(rng):
    n = 1001
    k = np.arange(n)
    x = 3.0 + 0.002 * (k - 500) + 0.1 * np.sin(2 * np.pi * k / 50)
    xm, tm = detrend(x, "mean")
    assert tm.kind == "mean" and tm.slope == 0.0
    assert tm.offset == pytest.approx(np.mean(x), rel=1e-15)
    assert_allclose(xm, x - np.mean(x), rtol=0, atol=1e-15)
    xl, tl = detrend(x, "linear")
    # np.polyfit is an independent least-squares line: slope and the value at the middle
    slope, icpt = np.polyfit(k, x, 1)
    assert tl.slope == pytest.approx(slope, rel=1e-10)
    assert tl.offset == pytest.approx(icpt + slope * 500, rel=1e-12)
    assert_allclose(xl, x - np.polyval([slope, icpt], k), rtol=0, atol=1e-12)
    x0, t0 = detrend(x, None)
    assert t0.offset == 0.0 and np.array_equal(x0, x) and x0 is not x


def test_detrend_bad_kind():
    with pytest.raises(ParameterError, match="detrend='quadratic'"):
        detrend(np.ones(4), "quadratic")


def test_decimate_keeps_the_pass_band_and_removes_aliases(rng):
    # A tone at 0.05 fs passes unchanged in amplitude and phase (zero-phase filter); a tone
    # at 0.45 fs, which would alias to 0.05 fs_new after decimation by 10 without a filter,
    # is removed to the Kaiser window's stop-band level (beta = 5: about -50 dB).
    fs, n, q = 1000.0, 20_000, 10
    t = np.arange(n) / fs
    keep = np.sin(2 * np.pi * 5.0 * t + 0.3)
    alias = np.sin(2 * np.pi * 450.0 * t)
    ud, yd = decimate(keep + alias, 2 * keep, q)
    assert ud.size == n // q
    td = np.arange(ud.size) * q / fs
    inner = slice(50, -50)  # away from the ends' line extension
    assert_allclose(ud[inner], np.sin(2 * np.pi * 5.0 * td + 0.3)[inner], rtol=0, atol=5e-3)
    assert_allclose(yd, 2 * ud - 2 * scipy.signal.resample_poly(alias, 1, q, padtype="line"),
                    rtol=0, atol=1e-12)


def test_decimate_preserves_a_loops_response(rng):
    # Input and output through the same linear-phase filter: the response of a low-pass
    # well inside the new band is unchanged. Noise-free, so the H1 estimate's only error
    # is the segments' leakage (impulse response ~ 20 samples at 200 Hz against
    # 1024-sample segments): well under 0.1 dB and 0.5 deg.
    fs, q = 1000.0, 5
    u = rng.standard_normal(60_000)
    b, a = scipy.signal.butter(2, 10.0, fs=fs)
    y = scipy.signal.lfilter(b, a, u)
    ud, yd = decimate(u, y, q)
    from ehss.frequency import h1_estimate

    frf = h1_estimate(ud, yd, fs / q, nperseg=1024)
    band = (frf.freq_hz >= 1.0) & (frf.freq_hz <= 40.0)  # 0.8 of the new Nyquist = 80 Hz
    _, h = scipy.signal.freqz(b, a, worN=frf.freq_hz[band], fs=fs)
    ratio = frf.response[band] / h
    assert np.max(np.abs(20 * np.log10(np.abs(ratio)))) < 0.1
    assert np.max(np.abs(np.degrees(np.angle(ratio)))) < 0.5


def test_decimate_checks():
    u = np.ones(1000)
    with pytest.raises(ParameterError, match="must be >= 1"):
        decimate(u, u, 0)
    with pytest.raises(TypeError, match="factor=2.5 must be an integer"):  # a wrong type
        decimate(u, u, 2.5)
    with pytest.raises(DataError, match="fewer than 256"):
        decimate(u, u, 5)
    out_u, _ = decimate(u, u, 1)
    assert np.array_equal(out_u, u)


def test_content_edge_of_band_limited_noise(rng):
    # White noise low-passed at 50 Hz (8th order): 99 % of the power lies below ~50 Hz,
    # well above 25 Hz; resolved to 8 fs / n = 0.4 Hz.
    fs = 1000.0
    x = scipy.signal.sosfilt(scipy.signal.butter(8, 50.0, fs=fs, output="sos"),
                             rng.standard_normal(20_000))
    edge = content_edge_hz(x, fs)
    assert 40.0 < edge < 60.0
    with pytest.raises(DataError, match="constant"):
        content_edge_hz(np.ones(100), fs)


def test_auto_decimation_follows_the_band_and_the_record(rng):
    fs = 4000.0
    u = scipy.signal.sosfiltfilt(scipy.signal.butter(4, 15.0, fs=fs, output="sos"),
                                 rng.standard_normal(240_000))
    y = scipy.signal.lfilter(*scipy.signal.butter(2, 8.0, fs=fs), u)
    # the record's content ends near 15-20 Hz: fs / (6 * edge) ~ 33-44
    q = auto_decimation(u, y, fs)
    assert 30 <= q <= 50
    # a band above the content raises the highest frequency of interest: 4000 / (6 * 100)
    assert auto_decimation(u, y, fs, band_hz=(0.1, 100.0)) == 6
    # a band below it does not lower it (the loop's own response still counts)
    assert auto_decimation(u, y, fs, band_hz=(0.1, 2.0)) == q
    # a record not oversampled is left alone
    w = rng.standard_normal(5000)
    assert auto_decimation(w, w, 100.0) == 1


@settings(max_examples=50, deadline=None)
@given(hnp.arrays(np.float64, st.integers(2, 200),
                  elements=st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False)))
def test_detrend_linear_invariants(x):
    # What is left is orthogonal to a constant and to a ramp, and the removed line plus
    # the rest gives back the signal (to rounding of values up to 1e6).
    xl, tr = detrend(x, "linear")
    k = np.arange(x.size) - (x.size - 1) / 2.0
    scale = 1.0 + np.max(np.abs(x))
    assert abs(np.sum(xl)) <= 1e-9 * scale * x.size
    assert abs(np.dot(k, xl)) <= 1e-9 * scale * x.size**2
    np.testing.assert_allclose(xl + tr.offset + tr.slope * k, x, rtol=0, atol=1e-9 * scale)
