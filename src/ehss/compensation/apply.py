"""Compensate a reference with the inverse of an identified closed-loop model, safely."""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Any, TypedDict, Unpack

import numpy as np

from ehss._checks import as_signal, check_fs
from ehss.compensation.checks import (
    DEFAULT_MAX_GAIN,
    DEFAULT_MIN_GAIN,
    DriveCheck,
    DriveLimits,
    check_at_rest,
    checked_drive,
    fade_to_rest,
)
from ehss.compensation.inverse import InverseModel, design_inverse
from ehss.compensation.inverse_model import _fft_band_limit
from ehss.compensation.rates import RATE_RTOL, rate_factor, to_model_rate, to_record_rate
from ehss.errors import EhssWarning, ParameterError
from ehss.identification.model import ArmaxModel

__all__ = ["compensate", "compensation", "CompensateKeywords", "Compensation", "apply_inverse",
           "OUTSIDE_BAND", "OUTSIDE_SHARE_WARN", "as_reference", "outside_band_note",
           "warn_if_outside_band", "model_offsets"]

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
    return as_signal(reference, "reference"), check_fs(fs)


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
        At the reference's rate ``fs``, about the model's operating point.

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


@dataclass(frozen=True, kw_only=True, eq=False)
class Compensation:
    """A checked drive and everything that made it (:func:`compensation`).

    Attributes
    ----------
    drive : ndarray, shape (n_samples,)
        The drive to play, with the operating point: ``u0 + F (r − y0)``.
    reference : ndarray, shape (n_samples,)
        The reference it was computed for, as compensated (faded when asked), with its
        operating point.
    fs : float
        Sample rate of both (Hz).
    inverse : InverseModel or None
        The inverse ``F`` (band limit ``inverse.band_hz``); None for a drive made
        otherwise (a drive-file iteration's update, checked alike).
    check : DriveCheck or None
        The drive's checks; None when a check failed and ``force`` kept the drive.
    failed_check : str or None
        The failed check's message when ``force`` kept the drive.
    warnings : tuple of str
        What the caller should be told (e.g. most of the reference outside the band).
    offsets : (float, float)
        The operating point ``(u0, y0)`` applied ((0, 0) for none).
    decimation : int
        Reference rate / model rate (1: the inverse ran at the reference's rate).
    """

    drive: np.ndarray = field(repr=False)
    reference: np.ndarray = field(repr=False)
    fs: float
    inverse: InverseModel | None = field(repr=False)
    check: DriveCheck | None
    failed_check: str | None
    warnings: tuple[str, ...]
    offsets: tuple[float, float]
    decimation: int


def model_offsets(model: Any, offsets: Any = "model") -> tuple[float, float]:
    """The operating point ``(u0, y0)`` a compensation applies.

    ``"model"``: the model's own (``ArmaxModel.offsets``, written by ``ehss identify``;
    (0, 0) when it carries none or is an :class:`InverseModel`); None: (0, 0); or a pair.
    """
    if isinstance(offsets, str) and offsets == "model":
        own = getattr(model, "offsets", None)
        return (0.0, 0.0) if own is None else (float(own[0]), float(own[1]))
    if offsets is None:
        return (0.0, 0.0)
    try:
        u0, y0 = (float(x) for x in offsets)
    except (TypeError, ValueError):
        raise ParameterError(f"offsets={offsets!r} must be 'model', None or a pair "
                             "(u0, y0)") from None
    if not (math.isfinite(u0) and math.isfinite(y0)):
        raise ParameterError(f"offsets={offsets!r} must be finite")
    return u0, y0


def _inverse(model: Any, rate: float, *, method: str, band_hz: Any, known: Any
             ) -> InverseModel:
    """The inverse to apply: the one given, or designed in the model's validated band."""
    if not isinstance(model, (InverseModel, ArmaxModel)):
        raise TypeError(f"model must be an ArmaxModel or an InverseModel, not "
                        f"{type(model).__name__}")
    rate_factor(rate, model.dt)  # a rate the model can be applied at, or DataError now
    if isinstance(model, InverseModel):
        return model
    if band_hz is None and model.band_hz is None:
        raise ParameterError(
            "the model carries no validated band (band_hz): give band_hz (e.g. the band "
            "where its validation's coherence was high); without a band limit the "
            "inverse amplifies everything the model never saw")
    return design_inverse(model, method=method, band_hz=band_hz, known=known)


def compensation(
    model: ArmaxModel | InverseModel,
    reference: Any,
    *,
    fs: float | None = None,
    method: str = "stable",
    band_hz: tuple[float, float] | None = None,
    preview: int | None = None,
    known: tuple[Any, Any] | None = None,
    offsets: Any = "model",
    fade_s: float | None = None,
    max_gain: float | None = DEFAULT_MAX_GAIN,
    min_gain: float | None = DEFAULT_MIN_GAIN,
    limits: DriveLimits | None = None,
    loop: str | None = None,
    params: Any = None,
    require_rest: bool = True,
    outside_band: str = "reference",
    force: bool = False,
) -> Compensation:
    """The checked drive that makes the identified closed loop follow ``reference``.

    One sequence, the one ``ehss compensate`` runs: the inverse designed inside the
    model's validated band, the reference taken about the model's operating point and
    (optionally) faded to rest, the inverse applied at the model's rate, and the drive
    checked (gain from above and below, explicit and rig limits) before it is returned:
    ``drive = u0 + F (r − y0)``.

    Parameters
    ----------
    model : ArmaxModel or InverseModel
        The identified closed loop (reference → measured output), or an already designed
        inverse.
    reference : ehss.signals.Signal, or array_like of shape (n_samples,) with ``fs``
        Desired output history (with the operating point, when the model carries one),
        at the model's rate or an integer multiple of it (see
        :mod:`ehss.compensation.rates`).
    fs : float, optional
        Sample rate of an array reference (Hz).
    method : {"stable", "zpetc", "zmetc"}
        Inverse design (:mod:`ehss.compensation.inverse`).
    band_hz : (lo, hi), optional
        Band limit of the inverse (Hz). Default the model's validated band.
    preview : int, optional
        Future samples usable (ZPETC, ZMETC), at the model's rate.
    known : (num, den), optional
        Known factor in series with the model.
    offsets : "model", None or (u0, y0)
        Operating point (:func:`model_offsets`): by default the model's own.
    fade_s : float, optional
        Fade the reference (about ``y0``) in and out over this many seconds.
    max_gain, min_gain, limits, loop, params
        Drive checks (:func:`~ehss.compensation.checks.check_drive`); None switches a
        gain bound off.
    require_rest : bool
        Refuse a reference that does not start and end at rest (after the fade).
    outside_band : {"reference", "zero"}
        What the drive holds outside the band limit (:func:`apply_inverse`).
    force : bool
        Keep a drive that fails its checks (``failed_check`` says which); a drive that is
        not finite is refused all the same.

    Returns
    -------
    Compensation

    Raises
    ------
    DataError
        Bad samples, or a sample rate that is not an integer multiple of the model's.
    ParameterError
        No band, an unusable model, a reference not at rest, a drive that is not finite,
        or (without ``force``) one that fails its checks (the message gives the numbers).
    """
    r, rate = as_reference(reference, fs)
    inverse = _inverse(model, rate, method=method, band_hz=band_hz, known=known)
    u0, y0 = model_offsets(model, offsets)
    r_dev = r - y0
    if fade_s is not None:
        r_dev = fade_to_rest(r_dev, rate, fade_s)
    if require_rest:
        check_at_rest(r_dev)
    drive_dev = apply_inverse(inverse, r_dev, rate, preview=preview, outside_band=outside_band)
    note = outside_band_note(r_dev, rate, inverse, outside_band)
    check, failure = checked_drive(drive_dev, r_dev, rate, force=force, max_gain=max_gain,
                                   min_gain=min_gain, limits=limits, loop=loop,
                                   params=params, drive_offset=u0)
    return Compensation(drive=u0 + drive_dev, reference=r_dev + y0, fs=rate, inverse=inverse,
                        check=check, failed_check=failure,
                        warnings=() if note is None else (note,), offsets=(u0, y0),
                        decimation=rate_factor(rate, inverse.dt))


class CompensateKeywords(TypedDict, total=False):
    """The keywords :func:`compensate` passes on to :func:`compensation`: all of its
    settings but ``fade_s`` and ``force``, with the same defaults."""

    fs: float | None
    method: str
    band_hz: tuple[float, float] | None
    preview: int | None
    known: tuple[Any, Any] | None
    offsets: Any
    max_gain: float | None
    min_gain: float | None
    limits: DriveLimits | None
    loop: str | None
    params: Any
    require_rest: bool
    outside_band: str


def compensate(
    model: ArmaxModel | InverseModel,
    reference: Any,
    **settings: Unpack[CompensateKeywords],
) -> np.ndarray:
    """Drive that makes the identified closed loop follow ``reference``, checked.

    :func:`compensation`'s drive, its warnings emitted as
    :class:`~ehss.errors.EhssWarning`: ``drive = u0 + F (r − y0)`` with the model's
    operating point ``(u0, y0)`` (none for a model that carries none).

    Parameters
    ----------
    model, reference
        As for :func:`compensation`.
    **settings
        The keywords of :class:`CompensateKeywords` (fs, method, band_hz, preview, known,
        offsets, max_gain, min_gain, limits, loop, params, require_rest, outside_band), as
        for :func:`compensation`.

    Returns
    -------
    drive : ndarray, shape (n_samples,)
        The drive of the :class:`Compensation`.

    Raises
    ------
    DataError, ParameterError
        As for :func:`compensation`; a drive that fails its checks is always refused.
    TypeError
        A keyword :func:`compensation` takes but this function does not (``fade_s``,
        ``force``), or no keyword of either.

    Examples
    --------
    >>> from ehss.identification.model import ArmaxModel
    >>> m = ArmaxModel(a=[1.0, -0.5], b=[0.5], delay=1, dt=1e-3, band_hz=(0.0, 100.0))
    >>> r = np.exp(-(((np.arange(1000) - 500) / 100) ** 2))  # at rest, in the band
    >>> u = compensate(m, r, fs=1000.0)
    >>> bool(np.allclose(m.simulate(u), r, rtol=0, atol=1e-9))
    True
    """
    unknown = sorted(settings.keys() - CompensateKeywords.__optional_keys__)
    if unknown:
        raise TypeError(f"compensate() got unexpected keyword arguments {unknown}")
    result = compensation(model, reference, **settings)
    for text in result.warnings:
        warnings.warn(text, EhssWarning, stacklevel=2)
    return result.drive


#: Share of the reference's power outside the inverse's band above which
#: :func:`compensate` warns that the drive compensates little of it.
OUTSIDE_SHARE_WARN = 0.1


def outside_band_note(r: np.ndarray, fs: float, inverse: InverseModel,
                      outside_band: str = "reference") -> str | None:
    """What to tell when more than :data:`OUTSIDE_SHARE_WARN` of the power of the
    reference ``r`` (at ``fs``, about the operating point) lies outside the band the
    inverse acts on: there the drive is the reference itself
    (``outside_band="reference"``) or nothing, not compensated. None otherwise."""
    total = float(np.sum(np.square(r - np.mean(r))))
    if not total > 0.0 or inverse.band_hz is None:  # no band limit: nothing lies outside
        return None
    inside = _fft_band_limit(r - np.mean(r), 1.0 / fs, inverse.band_hz, inverse.cutoff_hz)
    share = 1.0 - float(np.sum(np.square(inside))) / total
    if share <= OUTSIDE_SHARE_WARN:
        return None
    lo, hi = inverse.band_hz
    there = ("the drive is the reference itself there, uncompensated"
             if outside_band == "reference" else "the drive holds nothing of it")
    return (f"{100 * share:.0f} % of the reference's power lies outside the band "
            f"{lo:g}-{hi:g} Hz the inverse acts on (the model's validated band unless "
            f"given); {there}. Identify the loop on a record whose validation covers the "
            "reference's band, or give the band")


def warn_if_outside_band(r: np.ndarray, fs: float, inverse: InverseModel,
                         outside_band: str = "reference") -> None:
    """Warn (:class:`~ehss.errors.EhssWarning`) with :func:`outside_band_note`."""
    note = outside_band_note(r, fs, inverse, outside_band)
    if note is not None:
        warnings.warn(note, EhssWarning, stacklevel=3)
