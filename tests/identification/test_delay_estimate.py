"""The input delay estimated from a record's impulse response."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal

from ehss.errors import DataError, ParameterError
from ehss.identification import estimate_delay
from ehss.identification.delay import default_max_delay


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
