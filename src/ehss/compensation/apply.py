"""Compensate a reference with the inverse of an identified closed-loop model, safely."""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np

from ehss._checks import as_signal
from ehss.compensation.checks import DEFAULT_MAX_GAIN, DriveLimits, check_at_rest, check_drive
from ehss.compensation.inverse import InverseModel, design_inverse
from ehss.compensation.inverse_model import _fft_band_limit
from ehss.compensation.rates import RATE_RTOL, rate_factor, to_model_rate, to_record_rate
from ehss.errors import EhssWarning, ParameterError
from ehss.identification.model import ArmaxModel

__all__ = ["compensate", "apply_inverse", "OUTSIDE_BAND", "OUTSIDE_SHARE_WARN", "as_reference",
           "warn_if_outside_band"]

#: What a drive holds outside the inverse's band limit (:func:`apply_inverse`).
OUTSIDE_BAND = ("reference", "zero")



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
        if fs is not None and not math.isclose(float(fs), reference.fs, rel_tol=RATE_RTOL):
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


def apply_inverse(
    inverse: InverseModel,
    reference: Any,
    fs: float,
    *,
    preview: int | None = None,
    outside_band: str = "reference",
) -> np.ndarray:
    """The drive ``inverse`` gives for ``reference`` sampled at ``fs``, unchecked.

    Parameters
    ----------
    inverse : InverseModel
    reference : array_like, shape (n_samples,)
        About the model's operating point, at the model's rate or an integer multiple of
        it: the inverse then runs at the model's rate, between band-limited resampling
        (:mod:`ehss.compensation.rates`).
    fs : float
        Sample rate of ``reference``, Hz.
    preview : int, optional
        As for :meth:`InverseModel.apply`, in samples at the model's rate.
    outside_band : {"reference", "zero"}
        The inverse acts inside its band limit only (the band the model was validated
        over). Outside it the drive is, with ``"reference"`` (default), the reference
        itself: there the loop runs as it does without compensation, which a closed loop
        tracks well below its band (unit gain at DC) and attenuates above it, instead of
        not being driven at all. ``"zero"`` leaves nothing outside the band (what a
        correction of a drive-file iteration needs: its Q-filter).

    Returns
    -------
    drive : ndarray, shape (n_samples,)

    Raises
    ------
    DataError
        ``fs`` not an integer multiple of the model's rate, or bad samples.
    ParameterError
        Bad ``outside_band`` or ``preview``.
    """
    if outside_band not in OUTSIDE_BAND:
        raise ParameterError(f"outside_band={outside_band!r} must be one of {OUTSIDE_BAND}")
    r = as_signal(reference, "reference")
    q = rate_factor(fs, inverse.dt)
    drive = to_record_rate(inverse.apply(to_model_rate(r, q), preview=preview), q, r.size)
    if outside_band == "reference":
        # the complement of the band limit, zero-phase, at the reference's own rate
        drive += r - _fft_band_limit(r, 1.0 / fs, inverse.band_hz, inverse.cutoff_hz)
    return drive


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
    outside_band: str = "reference",
) -> np.ndarray:
    """Drive that makes the identified closed loop follow ``reference``, checked.

    Parameters
    ----------
    model : ArmaxModel or InverseModel
        The identified closed loop (reference → measured output), or an already designed
        inverse.
    reference : ehss.signals.Signal, or array_like of shape (n_samples,) with ``fs``
        Desired output history about the model's operating point, at the model's rate or
        an integer multiple of it (a model from a decimated record: the inverse then runs
        at the model's rate, see :mod:`ehss.compensation.rates`).
    fs : float, optional
        Sample rate of an array reference (Hz).
    method : {"stable", "zpetc", "zmetc"}
        Inverse design (see :mod:`ehss.compensation.inverse`); stable inversion, exact in
        the band, is the default.
    band_hz : (lo, hi), optional
        Band limit of the inverse (Hz). Default: the band the model was validated over,
        ``model.band_hz``; a model without one needs ``band_hz``.
    preview : int, optional
        Future samples usable (ZPETC, ZMETC), at the model's rate; ``None`` = the whole
        file is known.
    known : (num, den), optional
        Known factor in series with the model (see
        :func:`~ehss.compensation.inverse.design_inverse_tf`).
    max_gain, limits, loop, params
        Drive checks (:func:`~ehss.compensation.checks.check_drive`); ``max_gain=None``
        switches the gain check off.
    require_rest : bool
        Refuse a reference that does not start and end at rest
        (:func:`~ehss.compensation.checks.check_at_rest`; default).
    outside_band : {"reference", "zero"}
        What the drive holds outside the band limit (:func:`apply_inverse`): the
        reference itself, uncompensated (default), or nothing.

    Returns
    -------
    drive : ndarray, shape (n_samples,)

    Raises
    ------
    DataError
        Bad samples, or a sample rate that is not an integer multiple of the model's.
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
    rate_factor(rate, dt)  # a rate the model can be applied at, or DataError now
    if isinstance(model, ArmaxModel):
        if band_hz is None and model.band_hz is None:
            raise ParameterError(
                "the model carries no validated band (band_hz): give band_hz (e.g. the band "
                "where its validation's coherence was high); without a band limit the "
                "inverse amplifies everything the model never saw")
        inverse = design_inverse(model, method=method, band_hz=band_hz, known=known)
    if require_rest:
        check_at_rest(r)
    drive = apply_inverse(inverse, r, rate, preview=preview, outside_band=outside_band)
    warn_if_outside_band(r, rate, inverse, outside_band)
    if not np.all(np.isfinite(drive)):
        raise ParameterError("the compensated drive is not finite (badly conditioned model)")
    check_drive(drive, r, rate, max_gain=max_gain, limits=limits, loop=loop, params=params)
    return drive


#: Share of the reference's power outside the inverse's band above which
#: :func:`compensate` warns that the drive compensates little of it.
OUTSIDE_SHARE_WARN = 0.1


def warn_if_outside_band(r: np.ndarray, fs: float, inverse: InverseModel,
                         outside_band: str = "reference") -> None:
    """Warn (:class:`~ehss.errors.EhssWarning`) when more than
    :data:`OUTSIDE_SHARE_WARN` of the power of the reference ``r`` (at ``fs``) lies
    outside the band the inverse acts on: there the drive is the reference itself
    (``outside_band="reference"``) or nothing, not compensated."""
    total = float(np.sum(np.square(r - np.mean(r))))
    if not total > 0.0:
        return
    inside = _fft_band_limit(r - np.mean(r), 1.0 / fs, inverse.band_hz, inverse.cutoff_hz)
    share = 1.0 - float(np.sum(np.square(inside))) / total
    if share > OUTSIDE_SHARE_WARN:
        lo, hi = inverse.band_hz
        there = ("the drive is the reference itself there, uncompensated"
                 if outside_band == "reference" else "the drive holds nothing of it")
        warnings.warn(
            f"{100 * share:.0f} % of the reference's power lies outside the band "
            f"{lo:g}-{hi:g} Hz the inverse acts on (the model's validated band unless "
            f"given); {there}. Identify the loop on a record whose validation covers the "
            "reference's band, or give the band", EhssWarning, stacklevel=3)
