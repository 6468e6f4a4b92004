"""Checks of user-supplied sample arrays, shared by every public entry point.

A signal must be a 1-D array of finite real numbers; the error names the argument, the
first bad index (0-based, as Python counts) and its value.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ehss.errors import DataError

__all__ = ["as_signal", "as_record"]


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
