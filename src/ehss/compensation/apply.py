"""Compensate a reference with the inverse of an identified closed-loop model, safely."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ehss._checks import as_signal
from ehss.compensation.checks import DEFAULT_MAX_GAIN, DriveLimits, check_at_rest, check_drive
from ehss.compensation.inverse import InverseModel, design_inverse
from ehss.errors import DataError, ParameterError
from ehss.identification.model import ArmaxModel

__all__ = ["compensate", "as_reference"]

#: Relative mismatch allowed between the model's sample rate and the reference's.
_RATE_RTOL = 1e-6


def as_reference(reference: Any, fs: float | None) -> tuple[np.ndarray, float]:
    """A reference and its rate from the one accepted form: a Signal, or an array and fs.

    Parameters
    ----------
    reference : ehss.signals.Signal or array_like, shape (n_samples,)
    fs : float or None
        Sample rate (Hz) of an array; for a Signal it must be None or agree with it.

    Returns
    -------
    values : ndarray, shape (n_samples,)
    fs : float

    Raises
    ------
    ParameterError
        No rate for an array, a non-positive rate, or a rate different from the Signal's.
    DataError
        Bad samples.
    """
    from ehss.signals import Signal

    if isinstance(reference, Signal):
        if fs is not None and not math.isclose(float(fs), reference.fs, rel_tol=_RATE_RTOL):
            raise ParameterError(f"fs={fs!r} differs from the Signal's {reference.fs:g} Hz")
        return as_signal(reference.values, "reference"), reference.fs
    if fs is None:
        raise ParameterError("fs must be given with an array reference (or pass an "
                             "ehss.signals.Signal, which carries its rate)")
    if isinstance(fs, bool) or not isinstance(fs, (int, float, np.integer, np.floating)):
        raise TypeError(f"fs={fs!r} must be a number (Hz)")
    if not (math.isfinite(fs) and fs > 0):
        raise ParameterError(f"fs={fs!r} must be a finite number > 0 (Hz)")
    return as_signal(reference, "reference"), float(fs)


def compensate(
    model: ArmaxModel | InverseModel,
    reference: Any,
    *,
    fs: float | None = None,
    method: str = "stable",
    band_hz: tuple[float, float] | None = None,
    preview: int | None = None,
    known: tuple[Any, Any] | None = None,
    max_gain: float | None = DEFAULT_MAX_GAIN,
    limits: DriveLimits | None = None,
    loop: str | None = None,
    params: Any = None,
    require_rest: bool = True,
) -> np.ndarray:
    """Drive that makes the identified closed loop follow ``reference``, checked.

    Parameters
    ----------
    model : ArmaxModel or InverseModel
        The identified closed loop (reference → measured output), or an already designed
        inverse.
    reference : ehss.signals.Signal, or array_like of shape (n_samples,) with ``fs``
        Desired output history about the model's operating point, at the model's rate.
    fs : float, optional
        Sample rate of an array reference (Hz); must equal the model's.
    method : {"stable", "zpetc", "zmetc"}
        Inverse design (see :mod:`ehss.compensation.inverse`); stable inversion, exact in
        the band, is the default.
    band_hz : (lo, hi), optional
        Band limit of the inverse (Hz). Default: the band the model was validated over,
        ``model.band_hz``; a model without one needs ``band_hz``.
    preview : int, optional
        Future samples usable (ZPETC, ZMETC); ``None`` = the whole file is known.
    known : (num, den), optional
        Known factor in series with the model (see
        :func:`~ehss.compensation.inverse.design_inverse_tf`).
    max_gain, limits, loop, params
        Drive checks (:func:`~ehss.compensation.checks.check_drive`); ``max_gain=None``
        switches the gain check off.
    require_rest : bool
        Refuse a reference that does not start and end at rest
        (:func:`~ehss.compensation.checks.check_at_rest`; default).

    Returns
    -------
    drive : ndarray, shape (n_samples,)

    Raises
    ------
    DataError
        Bad samples, or a sample rate different from the model's.
    ParameterError
        No band, an unusable model, a reference not at rest, or a drive that fails its
        checks (the message gives the numbers).

    Examples
    --------
    >>> from ehss.identification.model import ArmaxModel
    >>> m = ArmaxModel(a=[1.0, -0.5], b=[0.5], delay=1, dt=1e-3, band_hz=(0.0, 100.0))
    >>> r = np.exp(-(((np.arange(1000) - 500) / 100) ** 2))  # at rest, in the band
    >>> u = compensate(m, r, fs=1000.0)
    >>> bool(np.allclose(m.simulate(u), r, rtol=0, atol=1e-9))
    True
    """
    r, rate = as_reference(reference, fs)
    if isinstance(model, InverseModel):
        inverse = model
        dt = model.dt
    elif isinstance(model, ArmaxModel):
        dt = model.dt
    else:
        raise TypeError(f"model must be an ArmaxModel or an InverseModel, not "
                        f"{type(model).__name__}")
    if not math.isclose(rate * dt, 1.0, rel_tol=_RATE_RTOL):
        raise DataError(
            f"reference is sampled at {rate:g} Hz but the model at {1.0 / dt:g} Hz "
            f"(dt={dt:g} s); resample the reference or identify at its rate"
        )
    if isinstance(model, ArmaxModel):
        if band_hz is None and model.band_hz is None:
            raise ParameterError(
                "the model carries no validated band (band_hz): give band_hz (e.g. the band "
                "where its validation's coherence was high); without a band limit the "
                "inverse amplifies everything the model never saw")
        inverse = design_inverse(model, method=method, band_hz=band_hz, known=known)
    if require_rest:
        check_at_rest(r)
    drive = inverse.apply(r, preview=preview)
    if not np.all(np.isfinite(drive)):
        raise ParameterError("the compensated drive is not finite (badly conditioned model)")
    check_drive(drive, r, rate, max_gain=max_gain, limits=limits, loop=loop, params=params)
    return drive
