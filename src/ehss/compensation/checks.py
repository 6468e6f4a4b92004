"""Checks of a compensated drive before it is written or played, and of its reference.

An inverse model is only as good as the model over the band it was validated in. Outside
that band, or where the model says the loop barely transmits, the inverse asks for more
than the loop can give, and the drive grows far beyond the reference. These checks stop
such a drive with the numbers instead of letting it reach a rig:

* **Gain.** The drive's RMS and peak (about the operating point) against the
  reference's. A closed loop used within its bandwidth passes its reference with a gain
  near 1; even at the edge of its validated band (-3 dB to -6 dB for a loop identified up
  to its bandwidth) the exact inverse asks for 1.4-2× there, and a broadband reference
  has most of its power below that edge. A drive 3× the reference's RMS (+9.5 dB across
  the reference's whole spectrum) therefore means the inverse amplifies where the model
  says the loop attenuates by 10 dB or more, i.e. outside what the model can be trusted
  for: :data:`DEFAULT_MAX_GAIN` = 3, applied to both the RMS and the peak ratio. The
  same reasoning bounds it from below: a drive whose RMS is under 1/3 of the reference's
  (−9.5 dB across the reference's whole spectrum) means the model says the loop
  amplifies by 10 dB or more where it is used, which a closed servo loop does not do (unit
  gain at DC; at its phase crossover a loop with the 6 dB gain margin ehss tunes for has
  |T| ≤ 1/(1 − 1/2) = 2, +6 dB, and less elsewhere). Such a drive comes from a model whose
  gain is wrong (a scale or unit error, huge B coefficients) and would leave the rig
  nearly still: :data:`DEFAULT_MIN_GAIN` = 1/3 on the RMS ratio.
* **Rig limits.** With a parameter set and the loop the drive is played into, the drive
  must respect the same limits as any reference of that loop, :func:`check_rig`, the
  one check ``ehss simulate`` applies to what it plays
  (:func:`ehss.signals.check_feasible`: stroke, velocity, the acceleration loop's
  acceleration and generated motion, force); a drive for the open loop (``"valve"``)
  must stay within the valve's full-scale command. Explicit :class:`DriveLimits` bound
  the drive's value, first and second derivatives (finite differences).
* **At rest.** A rig starts and ends a test at rest; a reference that starts or ends away
  from its operating point would make the drive (and the rig) jump.
  :func:`check_at_rest` asks for a fade (:func:`fade_to_rest`) instead.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from ehss._checks import as_signal, check_fs, check_real
from ehss.errors import ParameterError
from ehss.workflow.options import check_fields, option

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

__all__ = [
    "DEFAULT_MAX_GAIN",
    "DEFAULT_MIN_GAIN",
    "REST_TOLERANCE",
    "DriveLimits",
    "DriveCheck",
    "check_drive",
    "check_rig",
    "checked_drive",
    "check_at_rest",
    "fade_to_rest",
]

#: Default bound on the drive-to-reference RMS and peak ratios (see the module notes).
DEFAULT_MAX_GAIN = 3.0

#: Default lower bound on the drive-to-reference RMS ratio (see the module notes).
DEFAULT_MIN_GAIN = 1.0 / DEFAULT_MAX_GAIN

#: A reference is at rest at an end when it is within this fraction of its peak of zero.
REST_TOLERANCE = 0.01

#: Loops whose drive limits :meth:`DriveLimits` knows from a parameter set.
LOOPS = ("position", "acceleration", "force", "valve")


def _bound(value: Any, name: str) -> float | None:
    """A bound of a check: a positive number, or None for none."""
    return None if value is None else check_real(value, name, lo=0.0, lo_open=True)


@dataclass(frozen=True, kw_only=True)
class DriveLimits:
    """Explicit bounds on a drive, in the units of the model's input.

    Each field is declared once with its check and, for ``ehss compensate``, its flag
    (:func:`ehss.workflow.options.option`); ``max_abs`` has two there, ``--max-stroke``
    and ``--max-command``, which the command declares.

    Attributes
    ----------
    max_abs : float, optional
        Bound on ``|u|`` (stroke in m for a position drive, command in V for a valve
        drive, ...).
    max_rate : float, optional
        Bound on ``|du/dt|`` (velocity for a position drive), by finite differences.
    max_rate2 : float, optional
        Bound on ``|d²u/dt²|`` (acceleration for a position drive).
    """

    max_abs: float | None = option(None, check=_bound)
    max_rate: float | None = option(None, check=_bound, flag="--max-velocity", type=float,
                                    metavar="X_PER_S", help="bound on |d drive/dt|")
    max_rate2: float | None = option(None, check=_bound, flag="--max-acceleration",
                                     type=float, metavar="X_PER_S2",
                                     help="bound on |d² drive/dt²|")

    def __post_init__(self) -> None:
        check_fields(self)


class _Figures:
    """A dataclass of figures that a sidecar or log records as JSON."""

    def to_dict(self: DataclassInstance) -> dict[str, Any]:
        """JSON-ready figures (every field; containers copied)."""
        return dataclasses.asdict(self)


@dataclass(frozen=True, kw_only=True)
class DriveCheck(_Figures):
    """What :func:`check_drive` measured (drive and reference about the operating point).

    Attributes
    ----------
    rms_gain, peak_gain : float
        ``rms(drive) / rms(reference)`` and ``max|drive| / max|reference|``.
    max_gain : float or None
        The bound they were held to (None: not checked).
    min_gain : float or None
        The lower bound ``rms_gain`` was held to (None: not checked).
    peak_abs, peak_rate, peak_rate2 : float
        Peak of ``|u0 + u|``, ``|du/dt|`` and ``|d²u/dt²|`` (finite differences).
    rig : dict
        Peaks checked against the rig's limits (empty when no parameter set was given).
    """

    rms_gain: float
    peak_gain: float
    max_gain: float | None
    min_gain: float | None = None
    peak_abs: float
    peak_rate: float
    peak_rate2: float
    rig: dict


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x * x)))


def check_drive(
    drive: Any,
    reference: Any,
    fs: float,
    *,
    max_gain: float | None = DEFAULT_MAX_GAIN,
    min_gain: float | None = DEFAULT_MIN_GAIN,
    limits: DriveLimits | None = None,
    loop: str | None = None,
    params: Any = None,
    drive_offset: float = 0.0,
) -> DriveCheck:
    """Check a drive against the reference it was computed for and the rig's limits.

    Parameters
    ----------
    drive, reference : array_like, shape (n_samples,)
        Drive and reference about the operating point (deviations), same length.
    fs : float
        Sample rate (Hz), for the finite-difference rates.
    max_gain : float or None
        Bound on the RMS and peak ratios drive/reference (:data:`DEFAULT_MAX_GAIN`;
        None: not checked).
    min_gain : float or None
        Lower bound on the RMS ratio drive/reference (:data:`DEFAULT_MIN_GAIN`; None: not
        checked).
    limits : DriveLimits, optional
        Explicit bounds.
    loop : {"position", "acceleration", "force", "valve"}, optional
        With ``params``: the loop the drive is played into, whose limits it must respect.
    params : RigParams, optional
        Parameter set of the rig.
    drive_offset : float
        Operating point ``u0`` of the drive: the value and rig limits apply to
        ``drive_offset + drive`` (the gains to the deviation).

    Returns
    -------
    DriveCheck

    Raises
    ------
    ParameterError
        A bound is exceeded (the message gives the figure and the bound), or a bad
        option.
    DataError
        Non-finite or mismatched signals.
    """
    u = as_signal(drive, "drive")
    r = as_signal(reference, "reference")
    if u.size != r.size:
        raise ParameterError(f"drive and reference differ in length ({u.size} != {r.size})")
    fs = check_fs(fs)
    max_gain = _bound(max_gain, "max_gain")
    min_gain = _bound(min_gain, "min_gain")
    if limits is not None and not isinstance(limits, DriveLimits):
        raise TypeError(f"limits must be a DriveLimits, not {type(limits).__name__}")
    if (loop is None) != (params is None):
        raise ParameterError("loop and params go together (the rig's limits of that loop)")
    if loop is not None and loop not in LOOPS:
        raise ParameterError(f"loop={loop!r} must be one of {LOOPS}")
    rms_r, peak_r = _rms(r), float(np.max(np.abs(r)))
    rms_gain = _rms(u) / rms_r if rms_r > 0 else math.inf
    peak_gain = float(np.max(np.abs(u))) / peak_r if peak_r > 0 else math.inf
    _check_gains(rms_gain, peak_gain, max_gain, min_gain)
    absolute = u + check_real(drive_offset, "drive_offset")
    peaks = _peaks(absolute, fs)
    if limits is not None:
        _check_limits(peaks, limits)
    rig = {} if loop is None else check_rig(absolute, loop, params, fs, what="drive")
    return DriveCheck(rms_gain=rms_gain, peak_gain=peak_gain, max_gain=max_gain,
                      min_gain=min_gain, peak_abs=peaks[0], peak_rate=peaks[1],
                      peak_rate2=peaks[2], rig=rig)


def _peaks(u: np.ndarray, fs: float) -> tuple[float, float, float]:
    """Peaks of ``|u|``, ``|du/dt|`` and ``|d²u/dt²|`` (finite differences)."""
    rate = np.diff(u) * fs
    rate2 = np.diff(u, 2) * fs * fs
    return (float(np.max(np.abs(u))), float(np.max(np.abs(rate))) if rate.size else 0.0,
            float(np.max(np.abs(rate2))) if rate2.size else 0.0)


def _check_gains(rms_gain: float, peak_gain: float, max_gain: float | None,
                 min_gain: float | None) -> None:
    """Refuse a drive far larger than its reference, or far smaller."""
    if max_gain is not None:
        for what, value in (("RMS", rms_gain), ("peak", peak_gain)):
            if value > max_gain:
                raise ParameterError(
                    f"the drive's {what} is {value:.3g}× the reference's (bound {max_gain:g}×): "
                    "the inverse amplifies where the model is not to be trusted; narrow the "
                    "band or re-identify")
    if min_gain is not None and rms_gain < min_gain:
        raise ParameterError(
            f"the drive's RMS is {rms_gain:.3g}× the reference's (bound {min_gain:.3g}×): the "
            "model says the loop amplifies the reference by 10 dB or more, which a closed "
            "servo loop does not; check the model's gain (units, scale) or re-identify")


def _check_limits(peaks: tuple[float, float, float], limits: DriveLimits) -> None:
    """Refuse a drive whose peak, rate or second derivative exceeds the explicit bounds."""
    bounds = (limits.max_abs, limits.max_rate, limits.max_rate2)
    for name, value, bound in zip(("peak", "peak rate", "peak second derivative"), peaks,
                                  bounds, strict=True):
        if bound is not None and value > bound:
            raise ParameterError(f"drive {name} {value:.4g} exceeds the limit {bound:.4g}")


def check_rig(values: Any, loop: str, params: Any, fs: float, *, step: bool = False,
              what: str | None = None) -> dict[str, float]:
    """Refuse what a loop of the rig would be asked to play beyond its limits.

    The one check of a played signal: ``ehss simulate`` applies it to its reference (a
    drive file included) and :func:`check_drive` to a drive, so a drive that passes here
    is played.

    Parameters
    ----------
    values : array_like, shape (n_samples,)
        The signal played (SI units of the loop; V for ``"valve"``), with its operating
        point.
    loop : {"position", "acceleration", "force", "valve"}
    params : RigParams
    fs : float
        Sample rate (Hz).
    step : bool
        A position step asks for an infinite reference velocity by design (the loop and
        the valve limit the actual one), so for it only the stroke is checked.
    what : str, optional
        Named at the start of the message (e.g. ``"drive"``).

    Returns
    -------
    dict
        The peaks checked.

    Raises
    ------
    ParameterError
        A limit is exceeded: the message gives the figure and the limit.
    """
    from ehss.signals import STROKE_MARGIN, check_feasible

    u = np.asarray(values, dtype=np.float64)
    prefix = "" if what is None else f"{what}: "
    if loop == "valve":
        full = float(params.valve.command_full_scale_v)
        peak = float(np.max(np.abs(u)))
        if peak > full:
            raise ParameterError(f"{prefix}peak valve command {peak:.4g} V exceeds "
                                 f"valve.command_full_scale_v={full:.4g} V")
        return {"peak_command_v": peak}
    if step and loop == "position":
        stroke = STROKE_MARGIN * params.actuator.stroke_m
        peak = float(np.max(np.abs(u)))
        if peak > stroke:
            raise ParameterError(
                f"{prefix}position step to {peak:.4g} m exceeds {STROKE_MARGIN:.0%} of the "
                f"stroke ({stroke:.4g} m of actuator.stroke_m={params.actuator.stroke_m!r})")
        return {"peak_displacement_m": peak}
    try:
        return check_feasible(u, loop, params, fs)
    except ParameterError as exc:
        raise ParameterError(f"{prefix}{exc}") from None


def checked_drive(
    drive: np.ndarray,
    reference: np.ndarray,
    fs: float,
    *,
    force: bool = False,
    **checks: Any,
) -> tuple[DriveCheck | None, str | None]:
    """:func:`check_drive` as a compensation applies it before a drive is written.

    Parameters
    ----------
    drive, reference : ndarray, shape (n_samples,)
        About the operating point.
    fs : float
    force : bool
        Keep a drive that fails its checks: the failure is returned instead of raised.
    **checks
        ``max_gain``, ``min_gain``, ``limits``, ``loop``, ``params``, ``drive_offset``
        of :func:`check_drive`.

    Returns
    -------
    check : DriveCheck or None
        None when a check failed (with ``force``).
    failure : str or None
        The failed check's message (with ``force``).

    Raises
    ------
    ParameterError
        A drive that is not finite (a badly conditioned model: never written, even with
        ``force``), or, without ``force``, one that fails a check.
    """
    if not np.all(np.isfinite(drive)):
        raise ParameterError("the compensated drive is not finite (a badly conditioned "
                             "model?)")
    try:
        return check_drive(drive, reference, fs, **checks), None
    except ParameterError as exc:
        if not force:
            raise
        return None, str(exc)


def check_at_rest(reference: Any, *, tolerance: float = REST_TOLERANCE) -> None:
    """Raise if a reference (about its operating point) does not start and end at rest.

    Parameters
    ----------
    reference : array_like, shape (n_samples,)
    tolerance : float
        Allowed ``|r[0]|`` and ``|r[-1]|`` as a fraction of ``max|r|``
        (:data:`REST_TOLERANCE`: the rig jumps by at most 1 % of the test's peak).

    Raises
    ------
    DataError
        Bad samples.
    ParameterError
        The reference starts or ends away from rest; the message says by how much and
        asks for a fade.
    """
    r = as_signal(reference, "reference")
    peak = float(np.max(np.abs(r)))
    for end, value in (("starts", r[0]), ("ends", r[-1])):
        if abs(value) > tolerance * peak:
            raise ParameterError(
                f"the reference {end} at {value:.4g} (about the operating point), "
                f"{abs(value) / peak:.1%} of its peak {peak:.4g}: the drive would jump at the "
                "start or end of the test; fade it in and out (--fade SECONDS, "
                "ehss.compensation.fade_to_rest)")


def fade_to_rest(reference: Any, fs: float, fade_s: float) -> np.ndarray:
    """Raised-cosine fade-in and fade-out of ``fade_s`` seconds towards 0 at both ends."""
    from ehss.signals import with_fade

    r = as_signal(reference, "reference")
    return np.asarray(with_fade(r, fs=fs, fade_in_s=fade_s, fade_out_s=fade_s))
