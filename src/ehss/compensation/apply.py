"""Compensate a reference with the inverse of an identified closed-loop model."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ehss.compensation.inverse import InverseModel, _as_reference, design_inverse
from ehss.errors import DataError

__all__ = ["compensate", "reference_rate"]

#: Relative mismatch allowed between the model's sample rate and the reference's.
_RATE_RTOL = 1e-6


def reference_rate(reference: Any) -> float | None:
    """Sample rate (Hz) carried by a reference object, or ``None`` for a bare array."""
    for name in ("fs", "fs_hz", "sample_rate_hz"):
        fs = getattr(reference, name, None)
        if fs is not None:
            return float(fs)
    return None


def _signal_values(reference: Any) -> Any:
    for name in ("values", "data", "x", "y", "samples"):
        v = getattr(reference, name, None)
        if isinstance(v, np.ndarray):
            return v
    return reference


def compensate(
    model: Any,
    reference: Any,
    *,
    method: str = "zpetc",
    band_hz: tuple[float, float] | None = None,
    preview: int | None = None,
    fs: float | None = None,
    **options: Any,
) -> np.ndarray:
    """Drive that makes the identified closed loop follow ``reference``.

    Parameters
    ----------
    model : ArmaxModel or InverseModel
        The identified closed loop (reference → measured output), or an already designed
        inverse.
    reference : array_like, shape (n_samples,), or Signal
        Desired output history, sampled at ``model.fs``. A ``Signal`` (anything with an
        ``fs`` attribute) has its rate checked.
    method : {"zpetc", "zmetc"}
        Inverse design (see :mod:`ehss.compensation.inverse`).
    band_hz : (lo, hi), optional
        Zero-phase band limit of the drive (Hz).
    preview : int, optional
        Future samples usable; ``None`` = the whole file is known.
    fs : float, optional
        Sample rate of a bare-array reference, checked against the model's.
    **options
        Passed to :func:`~ehss.compensation.inverse.design_inverse_tf`.

    Returns
    -------
    drive : ndarray, shape (n_samples,)

    Raises
    ------
    DataError
        Empty, non-finite reference, or sample rate different from the model's.
    ParameterError
        Unusable model (unstable, ``b`` all zero, ...).

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> m = SimpleNamespace(a=[1.0, -0.5], b=[0.5], delay=1, dt=1e-3)
    >>> compensate(m, [0.0, 0.0, 1.0, 1.0]).tolist()
    [0.0, 2.0, 1.0, 1.0]
    """
    model_dt = getattr(model, "dt", None)
    given = reference_rate(reference)
    if given is None:
        given = fs
    elif fs is not None and not math.isclose(given, fs, rel_tol=_RATE_RTOL):
        raise DataError(f"reference sample rate {given:g} Hz differs from fs={fs:g} Hz")
    if given is not None and model_dt is not None and model_dt > 0 \
            and not math.isclose(given * model_dt, 1.0, rel_tol=_RATE_RTOL):
        raise DataError(
            f"reference is sampled at {given:g} Hz but the model at {1.0 / model_dt:g} Hz "
            f"(dt={model_dt:g} s); resample the reference or identify at its rate"
        )
    if isinstance(model, InverseModel):
        inverse = model
    else:
        inverse = design_inverse(model, method=method, band_hz=band_hz, **options)
    r = _as_reference(_signal_values(reference))
    return inverse.apply(r, preview=preview)
