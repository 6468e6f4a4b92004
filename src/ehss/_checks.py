"""Checks of user-supplied values, shared by every public entry point.

One error type per kind of mistake, everywhere in ehss:

- a value of the wrong Python type (a string where a number is expected, a bool where
  a count is, a float where an integer is) raises :class:`TypeError`;
- a value of the right type that is out of range, not finite, not among the choices or
  inconsistent (a band whose lower edge is not below its upper edge) raises
  :class:`~ehss.errors.ParameterError`, a :class:`ValueError`;
- bad samples (a signal that is not a finite 1-D array) raise
  :class:`~ehss.errors.DataError`, also a :class:`ValueError`.

Every message names the value and what is accepted, e.g.
``damping=-1.0 must be in (0, 100]``. Public functions check their arguments with these
functions rather than with their own ``isinstance`` tests, so that the same mistake is
reported the same way wherever it is made (``tests/test_layering.py`` keeps it so).

Scalars — :func:`check_real`, :func:`check_int`, :func:`check_bool`, :func:`check_choice`.
    Each takes the value and the name to show (``"valve.damping"``, ``"--fs"``) and
    returns the value converted to a plain Python type.

Rates and bands — :func:`check_fs`, :func:`check_band`.
    A sample rate in ``SAMPLE_RATE_RANGE_HZ``; a frequency band ``(lo, hi)`` in Hz with
    ``0 <= lo < hi``, and ``hi <= fs/2`` when the sample rate is known.

Sample arrays — :func:`as_signal`, :func:`as_record`.
    A signal must be a 1-D array of finite real numbers; the error names the argument,
    the first bad index (0-based, as Python counts) and its value.

The names are stable; new code should use these instead of writing its own checks.

Examples
--------
>>> check_real(2, "gain", lo=0.0, lo_open=True)
2.0
>>> check_int(3, "order", lo=0, hi=10)
3
>>> check_real(-1.0, "mass_kg", lo=0.0, lo_open=True)
Traceback (most recent call last):
...
ehss.errors.ParameterError: mass_kg=-1.0 must be in (0, inf)
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Collection, Iterable
from typing import Any

import numpy as np

from ehss.errors import DataError, ParameterError

__all__ = [
    "is_real",
    "is_integer",
    "check_real",
    "check_int",
    "check_int_list",
    "check_bool",
    "check_choice",
    "check_fs",
    "check_band",
    "format_range",
    "SAMPLE_RATE_RANGE_HZ",
    "SCALE_RANGE",
    "check_scale",
    "show",
    "as_signal",
    "as_record",
]


#: Sample rates ehss accepts, Hz: one sample every ~30 years up to 1 GHz. Beyond them the
#: time column is almost certainly not in seconds, and frequencies and periods lose
#: meaning (a step of 1e-310 s is not even a normal float).
SAMPLE_RATE_RANGE_HZ = (1e-9, 1e9)


#: Magnitudes of samples ehss processes without overflow or underflow: spectra and
#: coherence multiply four samples together (|S_uy|² / S_uu S_yy), so a sample beyond
#: 1e60 could overflow a float (1e308) once summed, and a variation below 1e-60 underflow.
SCALE_RANGE = (1e-60, 1e60)


def check_scale(x: np.ndarray, name: str) -> None:
    """Check that a measured signal varies, on a scale ehss can compute with.

    Parameters
    ----------
    x : ndarray, shape (n_samples,)
        Finite samples.
    name : str
        How the signal is named in messages (``"'run.csv': column 'u'"``).

    Raises
    ------
    DataError
        If ``x`` is constant, varies only in the last digits of its level, reaches
        beyond ``SCALE_RANGE[1]`` or varies by less than ``SCALE_RANGE[0]``. The message
        says to rescale (change the unit of) the signal.
    """
    lo, hi = SCALE_RANGE
    peak = float(np.max(np.abs(x)))
    if peak > hi:
        raise DataError(f"{name} reaches {peak:.3g}; ehss works with samples up to {hi:g} "
                        "in magnitude (spectra multiply four samples); rescale it, e.g. "
                        "change its unit")
    spread = float(np.max(np.abs(x - np.mean(x))))
    if spread == 0.0:
        raise DataError(f"{name} is constant (every sample is {float(x[0])!r}): it carries "
                        "no test signal")
    if spread <= 64 * np.finfo(np.float64).eps * peak:
        raise DataError(f"{name} varies by {spread:.3g} about a level of {peak:.6g}, only in "
                        "the last digits of its samples: it carries no usable test signal")
    if spread < lo:
        raise DataError(f"{name} varies by only {spread:.3g}; ehss needs variations of at "
                        f"least {lo:g}; rescale it, e.g. change its unit")


def format_range(
    lo: float | None, hi: float | None, *, lo_open: bool = False, hi_open: bool = False,
    unit: str = "",
) -> str:
    """An interval as people write it: ``[0, 1)``, ``(0, inf)``, ``[1, 1e+06] Hz``."""
    left = "(" if lo_open or lo is None else "["
    right = ")" if hi_open or hi is None else "]"
    a = "-inf" if lo is None else f"{lo:g}"
    b = "inf" if hi is None else f"{hi:g}"
    return f"{left}{a}, {b}{right}" + (f" {unit}" if unit else "")


def show(value: Any, limit: int = 60) -> str:
    """``repr(value)``, shortened in the middle when longer than ``limit`` characters."""
    text = repr(value)
    if len(text) <= limit:
        return text
    return f"{text[: limit // 2]}...{text[-10:]} ({len(text)} characters)"


def _in_range(x: float, lo: float | None, hi: float | None, lo_open: bool,
              hi_open: bool) -> bool:
    if lo is not None and (x < lo or (lo_open and x == lo)):
        return False
    return not (hi is not None and (x > hi or (hi_open and x == hi)))


def is_real(value: Any) -> bool:
    """Whether ``value`` is a real number (Python or NumPy; a bool is not).

    For the callers that raise their own error for a wrong type (a field of a model file
    is a :class:`DataError`); the others call :func:`check_real`.
    """
    return not isinstance(value, (bool, np.bool_)) and isinstance(value, numbers.Real)


def is_integer(value: Any) -> bool:
    """Whether ``value`` is an integer (Python or NumPy; a bool is not); see
    :func:`is_real`."""
    return not isinstance(value, (bool, np.bool_)) and isinstance(value, numbers.Integral)


def check_real(
    value: Any,
    name: str,
    *,
    lo: float | None = None,
    hi: float | None = None,
    lo_open: bool = False,
    hi_open: bool = False,
    unit: str = "",
) -> float:
    """``value`` as a finite float inside ``[lo, hi]`` (ends open on request).

    Parameters
    ----------
    value : int or float
        A real number (Python or NumPy; ``bool`` is refused).
    name : str
        How the value is named in messages.
    lo, hi : float, optional
        Bounds; None means unbounded on that side.
    lo_open, hi_open : bool, default False
        Exclude the bound itself.
    unit : str, optional
        Unit shown after the accepted range.

    Returns
    -------
    float

    Raises
    ------
    TypeError
        If ``value`` is not a real number (a string, None, a bool, complex, an array...).
    ParameterError
        If it is NaN, infinite, too large for a float or outside the range.
    """
    x = _real(value, name)
    accepted = format_range(lo, hi, lo_open=lo_open, hi_open=hi_open, unit=unit)
    if not math.isfinite(x):
        raise ParameterError(f"{name}={show(value)} must be finite, in {accepted}")
    if not _in_range(x, lo, hi, lo_open, hi_open):
        raise ParameterError(f"{name}={show(value)} must be in {accepted}")
    return x


def _real(value: Any, name: str) -> float:
    """``value`` as a float (maybe NaN or infinite); TypeError if it is not a real number."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name}={show(value)} must be a real number, not {type(value).__name__}")
    try:
        return float(value)
    except OverflowError:
        raise ParameterError(f"{name}={show(value)} is too large for a float") from None


def check_int(value: Any, name: str, *, lo: int | None = None, hi: int | None = None) -> int:
    """``value`` as a Python int inside ``[lo, hi]``.

    Raises
    ------
    TypeError
        If ``value`` is not an integer (a float such as ``2.0`` or ``1.5``, a string, a bool).
    ParameterError
        If it is outside the range.
    """
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name}={show(value)} must be an integer, not {type(value).__name__}")
    k = int(value)
    if not _in_range(k, lo, hi, False, False):
        raise ParameterError(f"{name}={show(value)} must be an integer in "
                             f"{format_range(lo, hi)}")
    return k


def check_int_list(value: Any, name: str, *, lo: int) -> list[int]:
    """``value`` (one integer or a collection of them) as a non-empty list of ints >= ``lo``.

    Raises
    ------
    TypeError
        If ``value`` or one of its items is not an integer (a float, a string, a bool).
    ParameterError
        If it is empty or an item is below ``lo``.
    """
    if isinstance(value, (str, bytes)) or not isinstance(value, (numbers.Integral, Iterable)):
        raise TypeError(f"{name}={show(value)} must hold integers >= {lo}, "
                        f"not {type(value).__name__}")
    values = [value] if isinstance(value, numbers.Integral) else list(value)
    for v in values:
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, numbers.Integral):
            raise TypeError(f"{name}={show(value)} must hold integers >= {lo}, "
                            f"not {type(v).__name__}")
        if v < lo:
            raise ParameterError(f"{name}={show(value)} must hold integers >= {lo}")
    if not values:
        raise ParameterError(f"{name}={show(value)} must list at least one {name}")
    return [int(v) for v in values]


def check_bool(value: Any, name: str) -> bool:
    """``value`` as a bool; only ``True``/``False`` are accepted (never ``"no"`` or 0).

    Raises
    ------
    TypeError
        If ``value`` is not a boolean.
    """
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name}={show(value)} must be true or false, not {type(value).__name__}")
    return bool(value)


def check_choice(value: Any, name: str, choices: Collection[Any]) -> Any:
    """``value`` if it is one of ``choices``.

    Raises
    ------
    TypeError
        If ``value`` is not of the type of the choices (e.g. a number where names are
        expected).
    ParameterError
        If it is not among them.
    """
    kinds = {type(c) for c in choices}
    if kinds and not isinstance(value, tuple(kinds)):
        raise TypeError(f"{name}={show(value)} must be one of {_listing(choices)}, "
                        f"not {type(value).__name__}")
    if value not in choices:
        raise ParameterError(f"{name}={show(value)} must be one of {_listing(choices)}")
    return value


def check_fs(fs: Any, name: str = "fs") -> float:
    """``fs`` as a sample rate in Hz, inside ``SAMPLE_RATE_RANGE_HZ``.

    Raises
    ------
    TypeError
        If ``fs`` is not a real number (the string ``"100"``, None, a bool...).
    ParameterError
        If it is not finite or outside ``SAMPLE_RATE_RANGE_HZ`` (zero or negative included).
    """
    lo, hi = SAMPLE_RATE_RANGE_HZ
    return check_real(fs, name, lo=lo, hi=hi, unit="Hz")


def check_band(
    band: Any, name: str = "band_hz", *, fs: float | None = None, below_nyquist: bool = False,
) -> tuple[float, float]:
    """``band`` as ``(lo, hi)`` in Hz with ``0 <= lo < hi`` (and ``hi <= fs/2``).

    Parameters
    ----------
    band : pair of real numbers
        The band's edges in Hz.
    name : str, default "band_hz"
        How the band is named in messages. A command-line option (a name starting with
        ``-``, such as ``"--band"``) is shown as it was typed: ``--band 5 1``.
    fs : float, optional
        Sample rate in Hz; when given, ``hi`` must not exceed the Nyquist frequency ``fs/2``.
    below_nyquist : bool, default False
        Require ``hi < fs/2`` strictly (e.g. when a taper must fit between ``hi`` and fs/2).

    Returns
    -------
    (float, float)

    Raises
    ------
    TypeError
        If ``band`` is not a pair, or an edge is not a real number.
    ParameterError
        If it does not have two edges, an edge is NaN or infinite, ``lo < 0``, ``lo >= hi``,
        or ``hi`` is above fs/2 (at fs/2 too with ``below_nyquist``).

    Examples
    --------
    >>> check_band((1, 20.5), fs=100.0)
    (1.0, 20.5)
    >>> check_band((5.0, 1.0), "--band")
    Traceback (most recent call last):
    ...
    ehss.errors.ParameterError: --band 5 1 must satisfy 0 <= LO < HI
    """
    try:
        if isinstance(band, (str, bytes)):
            raise TypeError
        edges = list(band)  # a 0-d array is Iterable yet cannot be iterated
    except TypeError:
        raise TypeError(f"{name}={show(band)} must be a pair (lo, hi) of numbers in Hz, "
                        f"not {type(band).__name__}") from None
    if len(edges) != 2:
        raise ParameterError(f"{name}={show(band)} must be a pair (lo, hi) in Hz, "
                             f"not {len(edges)} values")
    lo, hi = (_real(v, f"{name}[{i}]") for i, v in enumerate(edges))
    option = name.startswith("-")
    shown = f"{name} {lo:g} {hi:g}" if option else f"{name}=({lo:g}, {hi:g})"
    lo_name, hi_name = ("LO", "HI") if option else ("lo", "hi")
    if not (0.0 <= lo < hi and math.isfinite(hi)):
        finite = "" if math.isfinite(lo) and math.isfinite(hi) else ", both finite"
        raise ParameterError(f"{shown} must satisfy 0 <= {lo_name} < {hi_name}{finite}")
    if fs is not None:
        nyquist = 0.5 * check_fs(fs)
        if hi > nyquist or (below_nyquist and hi == nyquist):
            where = "above" if hi > nyquist else "at"
            below = "<" if below_nyquist else "<="
            raise ParameterError(
                f"{name} upper edge {hi:g} Hz is {where} fs/2 = {nyquist:g} Hz; {shown} "
                f"must satisfy 0 <= {lo_name} < {hi_name} {below} fs/2")
    return lo, hi


def _listing(choices: Collection[Any]) -> str:
    return ", ".join(repr(c) for c in choices)


def as_signal(x: Any, name: str, *, allow_empty: bool = False) -> np.ndarray:
    """``x`` as a contiguous float64 1-D array of finite values.

    Raises
    ------
    DataError
        If ``x`` is not numeric, not 1-D, empty (unless ``allow_empty``) or has a NaN/inf.
    """
    try:
        a = np.asarray(x)
        if a.dtype.kind not in "biuf":
            raise TypeError(f"dtype {a.dtype}")
        a = np.ascontiguousarray(a, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise DataError(f"{name} must be a 1-D array of numbers, not {exc}") from None
    if a.ndim != 1:
        raise DataError(f"{name} must be 1-D, got shape {a.shape}")
    if a.size == 0 and not allow_empty:
        raise DataError(f"{name} is empty")
    bad = np.flatnonzero(~np.isfinite(a))
    if bad.size:
        i = int(bad[0])
        raise DataError(
            f"{name}[{i}]={float(a[i])!r} is not finite ({bad.size} non-finite sample"
            f"{'s' if bad.size > 1 else ''})"
        )
    return a


def as_record(u: Any, y: Any) -> tuple[np.ndarray, np.ndarray]:
    """An input/output record: two finite 1-D signals of the same length."""
    u = as_signal(u, "u")
    y = as_signal(y, "y")
    if u.size != y.size:
        raise DataError(f"u and y must have the same length, got {u.size} and {y.size}")
    return u, y
