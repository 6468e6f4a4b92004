"""The shared argument checks: one error type per kind of mistake, one message per check."""

from __future__ import annotations

import numpy as np
import pytest

from ehss._checks import (
    SAMPLE_RATE_RANGE_HZ,
    check_band,
    check_fs,
    check_int_list,
    is_integer,
    is_real,
)
from ehss.errors import ParameterError
from ehss.frequency import h1_estimate
from ehss.preprocess import content_edge_hz, excitation_band
from ehss.signals import band_limited_random


# ------------------------------------------------------------------------- sample rate
@pytest.mark.parametrize("fs", [100, 100.0, np.float32(100.0), np.int64(100)])
def test_a_sample_rate_is_a_float(fs):
    assert check_fs(fs) == 100.0 and type(check_fs(fs)) is float


@pytest.mark.parametrize("fs", ["100", None, True, np.bool_(True), 100j, [100.0]])
def test_a_sample_rate_of_the_wrong_type_is_a_type_error(fs):
    with pytest.raises(TypeError, match=r"^fs=.* must be a real number, not "):
        check_fs(fs)


@pytest.mark.parametrize("fs", [0.0, -1.0, float("nan"), float("inf"),
                                2 * SAMPLE_RATE_RANGE_HZ[1]])
def test_a_sample_rate_out_of_range_is_a_parameter_error(fs):
    with pytest.raises(ParameterError, match=r"^fs=.* must be .*\[1e-09, 1e\+09\] Hz$"):
        check_fs(fs)


@pytest.mark.parametrize("call", [
    lambda u: h1_estimate(u, u, "100"),
    lambda u: content_edge_hz(u, "100"),
    lambda u: excitation_band(u, "100"),
    lambda u: band_limited_random(band_hz=(1, 10), rms=1.0, duration_s=1.0, fs="100",
                                  seed=1),
])
def test_public_functions_refuse_a_string_rate_alike(rng, call):
    # "100" used to pass as 100 Hz in some functions and fail in others
    with pytest.raises(TypeError, match=r"fs='100' must be a real number, not str"):
        call(rng.standard_normal(1000))


# ------------------------------------------------------------------------------ band
@pytest.mark.parametrize("band", [(0, 1), (0.5, 50.0), np.array([1.0, 2.0]), [3, 4.5]])
def test_a_band_is_two_floats(band):
    lo, hi = check_band(band, fs=100.0)
    assert (lo, hi) == (float(band[0]), float(band[1]))
    assert type(lo) is float and type(hi) is float


@pytest.mark.parametrize(("band", "match"), [
    ((2.0, 2.0), r"^band_hz=\(2, 2\) must satisfy 0 <= lo < hi$"),  # lo == hi: no band
    ((5.0, 1.0), r"^band_hz=\(5, 1\) must satisfy 0 <= lo < hi$"),
    ((-1.0, 1.0), r"^band_hz=\(-1, 1\) must satisfy 0 <= lo < hi$"),
    ((1.0, float("inf")), r"must satisfy 0 <= lo < hi, both finite$"),
    ((float("nan"), 1.0), r"must satisfy 0 <= lo < hi, both finite$"),
    ((1.0, 2.0, 3.0), r"must be a pair \(lo, hi\) in Hz, not 3 values"),
])
def test_a_bad_band_is_a_parameter_error(band, match):
    with pytest.raises(ParameterError, match=match):
        check_band(band)


@pytest.mark.parametrize("band", ["1 2", 3.0, None, (1.0, "2"), (True, 2.0)])
def test_a_band_of_the_wrong_type_is_a_type_error(band):
    with pytest.raises(TypeError, match=r"^band_hz(\[\d\])?=.* must be "):
        check_band(band)


def test_the_band_ends_at_nyquist_or_below_it():
    assert check_band((1.0, 50.0), fs=100.0) == (1.0, 50.0)  # at fs/2: allowed
    with pytest.raises(ParameterError, match=r"upper edge 50 Hz is at fs/2 = 50 Hz; "
                                             r"band_hz=\(1, 50\) must satisfy 0 <= lo < hi "
                                             r"< fs/2$"):
        check_band((1.0, 50.0), fs=100.0, below_nyquist=True)
    with pytest.raises(ParameterError, match=r"^band_hz upper edge 60 Hz is above fs/2 = "
                                             r"50 Hz; .* <= fs/2$"):
        check_band((1.0, 60.0), fs=100.0)
    with pytest.raises(TypeError, match="fs='100'"):
        check_band((1.0, 2.0), fs="100")


def test_a_command_line_band_is_shown_as_typed():
    with pytest.raises(ParameterError, match=r"^--band 5 1 must satisfy 0 <= LO < HI$"):
        check_band((5.0, 1.0), "--band")
    with pytest.raises(ParameterError, match=r"^--band upper edge 600 Hz is above fs/2 = "
                                             r"500 Hz; --band 1 600 must satisfy"):
        check_band((1.0, 600.0), "--band", fs=1000.0)


# ------------------------------------------------------------------ lists of integers
def test_a_list_of_integers():
    assert check_int_list(3, "na", lo=1) == [3]
    assert check_int_list((1, np.int64(2)), "na", lo=1) == [1, 2]
    with pytest.raises(ParameterError, match=r"^na=\[0\] must hold integers >= 1$"):
        check_int_list([0], "na", lo=1)
    with pytest.raises(ParameterError, match="must list at least one na"):
        check_int_list([], "na", lo=1)
    for bad in ([1.5], [True], "12", 2.0):
        with pytest.raises(TypeError, match=r"must hold integers >= 1, not "):
            check_int_list(bad, "na", lo=1)


@pytest.mark.parametrize(("value", "real", "integer"), [
    (1, True, True), (np.int32(3), True, True), (2.5, True, False), (np.float64(1.0), True, False),
    (float("nan"), True, False), (True, False, False), (np.bool_(False), False, False),
    ("1", False, False), (None, False, False), (1 + 0j, False, False), ([1], False, False),
])
def test_the_predicates_for_callers_with_errors_of_their_own(value, real, integer):
    # what a model file's field or a streaming sample is judged by; bools are not numbers
    assert (is_real(value), is_integer(value)) == (real, integer)
