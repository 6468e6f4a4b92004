"""The input delay estimated from a record's impulse response."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal

from ehss.errors import DataError, ParameterError
from ehss.identification import estimate_delay
from ehss.identification.delay import default_max_delay, scan_delays


@pytest.mark.parametrize("delay", [0, 1, 3, 17, 60])
def test_a_lag_behind_a_dead_time_is_found_under_output_noise(rng, delay):
    # a low-pass (b0 is the largest tap) behind `delay` samples, white input, output
    # noise at 5 % of the output's RMS: the FIR estimate is unbiased by that noise
    u = rng.standard_normal(6000)
    y = scipy.signal.lfilter(np.r_[np.zeros(delay), 0.3], [1.0, -0.7], u)
    y = y + 0.05 * np.std(y) * rng.standard_normal(u.size)
    assert estimate_delay(u, y) == delay


def test_an_output_that_does_not_respond_has_no_delay(rng):
    assert estimate_delay(rng.standard_normal(5000), rng.standard_normal(5000)) is None


def test_a_response_beyond_the_reach_is_not_guessed(rng):
    u = rng.standard_normal(5000)
    y = np.r_[np.zeros(30), u[:-30]]
    assert estimate_delay(u, y, max_delay=20) is None
    assert estimate_delay(u, y, max_delay=40) == 30


def test_the_reach_follows_the_record():
    # 10 samples a parameter: 10 taps beyond the last delay and 8 past outputs; at most 100
    assert default_max_delay(500) == 26
    assert default_max_delay(10**6) == 100
    assert default_max_delay(100) == 0


def test_bad_requests_say_why(rng):
    u = rng.standard_normal(200)
    with pytest.raises(DataError, match=r"200 samples are too few to estimate a delay up to "
                                        r"50 samples \(need at least 759\)"):
        estimate_delay(u, u, max_delay=50)
    with pytest.raises(ParameterError, match="max_delay"):
        estimate_delay(u, u, max_delay=-1)


def _tanks(rng, n=1024, tau=40.0, hold=25, delay=0):
    """Two cascaded first-order lags of `tau` samples each (a tank draining into
    another) behind `delay` samples, driven by levels held for `hold` samples, with
    2 % output noise: a record far slower than the taps can follow."""
    u = np.repeat(rng.uniform(-1.0, 1.0, n // hold + 1), hold)[:n]
    a = np.exp(-1.0 / tau)
    y = scipy.signal.lfilter(np.r_[np.zeros(delay + 1), (1 - a) ** 2],
                             np.convolve([1.0, -a], [1.0, -a]), u)
    return u, y + 0.02 * np.std(y) * rng.standard_normal(n)


def test_a_slow_record_proposes_delays_and_nb_over_its_rise(rng):
    u, y = _tanks(rng)
    scan = scan_delays(u, y)
    assert not scan.supported
    # the step response of two lags of 40 samples reaches 10 % at 0.53 tau = 21 samples
    # and 50 % at 1.68 tau = 67: the estimate's rise is of that size (within a fifth
    # below and 40 % above: 2 % noise on 1024 samples and 8 past outputs for a response
    # that the taps do not reach), so the candidates span from 0 to t10 and nb reaches
    # its cap of 6
    t10, t50 = scan.rise
    assert 0.8 * 21 < t10 < 1.4 * 21 and 0.8 * 67 < t50 < 1.4 * 67
    assert scan.delays[0] == 0 and scan.delays[-1] == min(t10, scan.max_delay)
    assert len(scan.delays) == 4 and scan.max_nb == 6


def test_a_supported_delay_is_the_same_in_each_half(rng):
    u = rng.standard_normal(4000)
    y = scipy.signal.lfilter(np.r_[np.zeros(5), 0.3], [1.0, -0.7], u)
    scan = scan_delays(u, y + 0.05 * np.std(y) * rng.standard_normal(u.size))
    assert scan.supported and scan.delay == 5 and scan.halves == (5, 5)
    assert scan.delays == (4, 5) and scan.max_nb == 3


def test_a_band_limited_oversampled_record_does_not_pin_its_delay(rng):
    # a 4th-order 30 Hz low-pass at 1 kHz, driven by noise band-passed to 2-100 Hz and
    # decimated by 3: nothing is excited near the new Nyquist frequency, the taps are
    # ill-determined, and the whole record and its halves place the delay apart
    fs = 1000.0
    sos = scipy.signal.butter(4, [2.0, 100.0], "bandpass", fs=fs, output="sos")
    u = scipy.signal.sosfiltfilt(sos, rng.standard_normal(20_000))
    y = scipy.signal.lfilter(*scipy.signal.butter(4, 30.0, fs=fs), u)
    y = y + 0.01 * np.std(y) * rng.standard_normal(u.size)
    scan = scan_delays(u, y)
    found = [d for d in (scan.whole, *scan.halves) if d is not None]
    assert not scan.supported
    assert len(found) < 3 or max(found) - min(found) > 1
    assert scan.delays[0] == 0 and len(scan.delays) > 1
