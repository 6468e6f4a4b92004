"""Drive-file iteration: correct a drive from what the loop did, converging or stopping.

Between two runs of a test the rig user has the reference ``r``, the drive ``u_k`` that
was played and the measured output ``y_k``. The learning update (iterative learning
control) is

.. math:: u_{k+1} = u_k + L\\,Q\\,F\\,(r - y_k),

with ``F`` an inverse of the loop and ``Q`` the band limit (the Q-filter: the update only
acts where the model was validated). Two inverses are offered:

* ``method="model"`` — ``F`` the inverse of the identified model
  (:mod:`ehss.compensation.inverse`, stable inversion by default), optionally of a model
  re-identified from the run;
* ``method="frf"`` — the non-parametric drive-file iteration of shaking-table
  controllers: ``F = γ²/Ĥ`` with ``Ĥ`` the H1 estimate drive → output of the last run and
  ``γ²`` its coherence. ``γ²/Ĥ`` is the Wiener-regularised inverse
  ``Ĥ^*/(|Ĥ|^2 + λ)`` with ``λ = |Ĥ|^2 (1-γ^2)/γ^2`` (the noise-to-signal ratio of the
  estimate): exact where the record is coherent, shrunk where it is not, and zero where
  the coherence is below :data:`MIN_COHERENCE`.

**Convergence.** With ``G`` the loop, the error contracts per frequency by ``|1 - L G
F|``. The default gain is the largest of 1, 1/2, 1/4, 1/8 for which the contraction
measured on the run (``G F`` from the run's own H1 estimate, inside the band where the
run is coherent, i.e. where the test has content) stays below :data:`MAX_CONTRACTION` —
stable for the model error the run shows. The error of each run is compared with that of
the run the update started from: when it grows, the update is refused and taken again
from the better drive with half the gain; after :data:`MAX_HALVINGS` refusals in a row
the iteration stops and hands back the best drive.

Each run is logged (:class:`RunRecord`): RMS and peak error, the normalised RMS error
``100 std(y - r)/std(r)``, the lag of the output behind the reference (J1 delay: the peak
of their cross-correlation, refined by a parabola), and the drive's gain.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.fft
import scipy.signal

from ehss._checks import as_signal, check_band, check_bool, check_int, check_real, show
from ehss.compensation.apply import Compensation, apply_inverse, model_offsets
from ehss.compensation.checks import _Figures, check_at_rest, checked_drive, fade_to_rest
from ehss.compensation.inverse import METHODS, _band_and_cutoff, design_inverse
from ehss.compensation.inverse_model import InverseModel, _fft_band_limit, band_taper
from ehss.compensation.rates import rate_factor
from ehss.errors import ParameterError
from ehss.preprocess import decimate
from ehss.workflow.options import check_fields, choice, option, optional, or_default

__all__ = [
    "corrected_drive",
    "UPDATE_METHODS",
    "UpdateOptions",
    "MAX_CONTRACTION",
    "MAX_HALVINGS",
    "MIN_COHERENCE",
    "JUDGE_COHERENCE",
    "CONTENT_FRACTION",
    "GAIN_STEPS",
    "RunRecord",
    "IterationState",
    "DriveUpdate",
    "run_record",
    "lag_samples",
    "learning_gain",
    "update_drive",
]

UPDATE_METHODS = ("model", "frf")

#: Largest per-frequency error contraction |1 - L G F| the default gain accepts.
MAX_CONTRACTION = 0.9

#: Candidate default gains, tried from the largest.
GAIN_STEPS = (1.0, 0.5, 0.25, 0.125)

#: Refused updates in a row (gain halvings) before the iteration stops.
MAX_HALVINGS = 3

#: Coherence below which the FRF inverse is zero.
MIN_COHERENCE = 0.5

#: Coherence from which ``G F`` is judged for the default gain: where the run's drive
#: carries the test's content (elsewhere the H1 estimate says more about the noise).
JUDGE_COHERENCE = 0.9

#: Fraction of its peak the drive's spectrum must reach where ``G F`` is judged (-30 dB).
CONTENT_FRACTION = 1e-3


# --------------------------------------------------------------------------- records
def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x * x)))


def lag_samples(reference: Any, output: Any) -> float:
    """Lag of ``output`` behind ``reference`` (samples): the J1 delay.

    The peak of the cross-correlation of the mean-removed signals, refined by a parabola
    through the peak and its neighbours; positive when the output lags.
    """
    r = as_signal(reference, "reference")
    y = as_signal(output, "output")
    r = r - r.mean()
    y = y - y.mean()
    n = scipy.fft.next_fast_len(2 * r.size)
    c = scipy.fft.irfft(np.conj(scipy.fft.rfft(r, n)) * scipy.fft.rfft(y, n), n)
    # c[k] = sum r(i) y(i + k): lags 0..N-1 then -(N-1)..-1
    i = int(np.argmax(c))
    lag = i if i < n // 2 else i - n
    c0, c1, c2 = c[i - 1], c[i], c[(i + 1) % n]
    den = c0 - 2.0 * c1 + c2
    frac = 0.5 * (c0 - c2) / den if den < 0 else 0.0
    return float(lag + frac)


@dataclass(frozen=True, kw_only=True)
class RunRecord(_Figures):
    """Log of one played run (reference, drive and output about the operating point).

    Attributes
    ----------
    rms_error, peak_error : float
        RMS and peak of ``y - r`` (units of the loop).
    nrmse_percent : float
        ``100 std(y - r) / std(r)``.
    lag_samples : float
        J1 delay of the output behind the reference (:func:`lag_samples`).
    drive_rms_gain, drive_peak_gain : float
        ``rms(u)/rms(r)`` and ``max|u| / max|r|``.
    """

    rms_error: float
    peak_error: float
    nrmse_percent: float
    lag_samples: float
    drive_rms_gain: float
    drive_peak_gain: float


def run_record(reference: Any, drive: Any, output: Any) -> RunRecord:
    """Measure one run (:class:`RunRecord`)."""
    r, u, y = _same_length(reference, drive, output)
    e = y - r
    return RunRecord(
        rms_error=_rms(e), peak_error=float(np.max(np.abs(e))),
        nrmse_percent=float(100.0 * np.std(e) / np.std(r)) if np.std(r) > 0 else math.inf,
        lag_samples=lag_samples(r, y),
        drive_rms_gain=_rms(u) / _rms(r) if _rms(r) > 0 else math.inf,
        drive_peak_gain=float(np.max(np.abs(u)) / np.max(np.abs(r)))
        if np.max(np.abs(r)) > 0 else math.inf,
    )


def _same_length(reference: Any, drive: Any, output: Any
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    r = as_signal(reference, "reference")
    u = as_signal(drive, "drive")
    y = as_signal(output, "output")
    if not r.size == u.size == y.size:
        raise ParameterError(
            f"reference, drive and output must have the same length, got {r.size}, "
            f"{u.size} and {y.size}")
    return r, u, y


# --------------------------------------------------------------------------- state
@dataclass(frozen=True, kw_only=True)
class IterationState:
    """Where the last update started from, to compare the next run with and back off.

    Attributes
    ----------
    base_drive : ndarray
        The drive the last accepted update started from (the best drive so far).
    correction : ndarray
        ``Q F (r - y)`` of that run; the next drive was ``base_drive + gain·correction``.
    gain : float
        Learning gain of the last update.
    base_rms_error : float
        RMS error of the run of ``base_drive``.
    halvings : int
        Refused updates in a row so far.
    """

    base_drive: np.ndarray = field(repr=False)
    correction: np.ndarray = field(repr=False)
    gain: float
    base_rms_error: float
    halvings: int = 0

    def __post_init__(self) -> None:
        # a state read back from a drive file's metadata may have been edited: refuse
        # what no update could have left
        check_real(self.gain, "gain", lo=0.0, hi=2.0, lo_open=True, hi_open=True)
        check_real(self.base_rms_error, "base_rms_error", lo=0.0)
        check_int(self.halvings, "halvings", lo=0, hi=MAX_HALVINGS)
        b = as_signal(self.base_drive, "base_drive")
        c = as_signal(self.correction, "correction")
        if b.size != c.size:
            raise ParameterError(f"base_drive and correction differ in length ({b.size} != "
                                 f"{c.size})")


@dataclass(frozen=True, kw_only=True)
class DriveUpdate:
    """One drive-file iteration (see :func:`update_drive`).

    Attributes
    ----------
    drive : ndarray
        The next drive to play (on ``stopped``: the best drive so far).
    record : RunRecord
        The run this update measured.
    accepted : bool
        Whether the run improved on the one the last update started from (False: the
        update was refused and the gain halved).
    stopped : bool
        The error grew :data:`MAX_HALVINGS` times in a row: iterate no more.
    gain : float
        Learning gain used for ``drive``.
    state : IterationState
        To pass to the next call.
    model : ArmaxModel or None
        Model whose inverse was used (None for ``method="frf"``).
    inverse : InverseModel or None
    message : str
        What was decided, in a sentence.
    """

    drive: np.ndarray = field(repr=False)
    record: RunRecord
    accepted: bool
    stopped: bool
    gain: float
    state: IterationState = field(repr=False)
    model: Any = field(repr=False, default=None)
    inverse: InverseModel | None = field(repr=False, default=None)
    message: str = ""


# --------------------------------------------------------------------------- operators
def _h1(u: np.ndarray, y: np.ndarray, fs: float) -> Any:
    from ehss.frequency import default_nperseg, h1_estimate

    return h1_estimate(u, y, fs, nperseg=default_nperseg(u.size, fs))


def _frf_inverse(u: np.ndarray, y: np.ndarray, fs: float, band: tuple[float, float],
                 cutoff: float | None) -> Any:
    """``f -> W(f) γ²(f) / Ĥ(f)`` from the run's H1 estimate (see the module notes)."""
    est = _h1(u, y, fs)
    lag = round(lag_samples(u, y))
    f = est.freq_hz
    # remove the loop's delay before interpolating, so the phase varies slowly
    h = est.response * np.exp(2j * np.pi * f * lag / fs)
    gamma2 = np.where(est.coherence >= MIN_COHERENCE, est.coherence, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = np.where(gamma2 > 0, gamma2 / h, 0.0)

    def response(freq: np.ndarray) -> np.ndarray:
        re = np.interp(freq, f, inv.real, left=inv.real[0], right=0.0)
        im = np.interp(freq, f, inv.imag, left=0.0, right=0.0)
        return (re + 1j * im) * np.exp(2j * np.pi * freq * lag / fs) * band_taper(
            freq, band, cutoff)

    return response


def learning_gain(u: Any, y: Any, fs: float, operator: Any, band: tuple[float, float],
                  *, candidates: tuple[float, ...] = GAIN_STEPS) -> float:
    """Largest gain L with ``|1 - L G F| <= MAX_CONTRACTION`` where the run is coherent.

    ``G`` is the run's H1 estimate drive → output, ``F`` the learning operator's
    frequency response (``operator(freq_hz)``, band limit included), judged inside
    ``band`` where the coherence is at least :data:`JUDGE_COHERENCE` (for a noisy run
    where it never is, :data:`MIN_COHERENCE`) and the drive has content (its spectrum
    within :data:`CONTENT_FRACTION` of its peak).

    Raises
    ------
    ParameterError
        No candidate contracts: the model error is too large for a stable update.
    """
    u = as_signal(u, "drive")
    y = as_signal(y, "output")
    est = _h1(u, y, fs)
    f = est.freq_hz
    # Where the drive has content: its Welch spectrum within 30 dB of its peak. Beyond the
    # test's band a coherent H1 can still come from window leakage of in-band content,
    # and then it is a weighted mean of G near the band edge, not G there.
    f_w, s_uu = scipy.signal.welch(u, fs, nperseg=est.nperseg)
    content = np.interp(f, f_w, s_uu) >= CONTENT_FRACTION * float(np.max(s_uu))
    in_band = (f >= band[0]) & (f <= band[1]) & content
    sel = in_band & (est.coherence >= JUDGE_COHERENCE)
    if not np.any(sel):  # a noisy run: judge where it is at least half coherent
        sel = in_band & (est.coherence >= MIN_COHERENCE)
    if not np.any(sel):
        raise ParameterError(
            f"the run is not coherent (γ² >= {MIN_COHERENCE}) anywhere in the band "
            f"{band[0]:g}-{band[1]:g} Hz: no stable learning gain can be chosen")
    loop_gain = est.response[sel] * operator(f[sel])
    worst = math.inf
    for gain in candidates:
        worst = float(np.max(np.abs(1.0 - gain * loop_gain)))
        if worst <= MAX_CONTRACTION:
            return float(gain)
    i = int(np.argmax(np.abs(1.0 - candidates[-1] * loop_gain)))
    raise ParameterError(
        f"the model's error in the band is too large for a stable update: "
        f"|1 - L·G·F| = {worst:.3g} at {f[sel][i]:.4g} Hz even for L = {candidates[-1]:g}; "
        "re-identify the loop or iterate with method 'frf'")


# --------------------------------------------------------------------------- options
def _gain(value: Any, name: str) -> float:
    return check_real(value, name, lo=0.0, hi=2.0, lo_open=True, hi_open=True)


def _known(value: Any, name: str) -> tuple[np.ndarray, np.ndarray]:
    """A known factor ``(num, den)`` in series with the model, as two float arrays."""
    if not isinstance(value, tuple) or len(value) != 2:
        raise ParameterError(f"{name} must be a pair (num, den) of polynomial "
                             f"coefficients, not {show(value)}")
    return as_signal(value[0], f"{name}[0]"), as_signal(value[1], f"{name}[1]")


def _orders(value: Any, name: str) -> tuple[int, int]:
    """``(na, nb)`` of a re-identified model."""
    if not isinstance(value, tuple) or len(value) != 2:
        raise ParameterError(f"{name} must be a pair (na, nb), not {show(value)}")
    return check_int(value[0], f"{name}[0]", lo=1), check_int(value[1], f"{name}[1]", lo=0)


@dataclass(frozen=True, kw_only=True, eq=False)
class UpdateOptions:
    """How a drive-file iteration corrects a drive (:func:`update_drive`, :func:`ehss.
    experiments.refinement.refine`).

    Attributes
    ----------
    method : {"model", "frf"}, default "model"
        Inverse used for the correction (see the module notes).
    inverse_method : {"stable", "zpetc", "zmetc"}, default "stable"
        Design of the model's inverse (:func:`~ehss.compensation.design_inverse`).
    band_hz : (lo, hi), optional
        Band of the Q-filter and of the inverse; default the model's validated band.
    gain : float, optional
        Learning gain in (0, 2); default chosen from the run (:func:`learning_gain`), or
        kept from the iteration's state.
    reidentify : bool, default False
        ``method="model"``: re-identify the loop from each run's drive → output (the
        model's orders and delay, RML) before inverting it.
    nc : int, optional
        Noise order of the re-identification (default: the model's).
    known : (num, den), optional
        Known factor in series with the model (kept as two float arrays).
    orders : (na, nb), optional
        Orders of the re-identified model without the known factor (default: the
        model's, less the known factor it stores).
    """

    method: str = option("model", check=choice(UPDATE_METHODS))
    inverse_method: str = option("stable", check=choice(METHODS))
    band_hz: tuple[float, float] | None = option(None, check=optional(check_band))
    gain: float | None = option(
        None, check=optional(_gain), flag="--gain", type=float, metavar="L",
        help="learning gain L in (0, 2) (default: the largest of 1, 1/2, 1/4, 1/8 that the "
        "run shows to contract the error)")
    reidentify: bool = option(
        False, check=check_bool, flag="--reidentify", action="store_true",
        help="re-identify the loop from the run before inverting it")
    nc: int | None = option(None, check=optional(lambda v, n: check_int(v, n, lo=0)))
    known: tuple[np.ndarray, np.ndarray] | None = option(None, check=optional(_known))
    orders: tuple[int, int] | None = option(None, check=optional(_orders))

    def __post_init__(self) -> None:
        check_fields(self)


# --------------------------------------------------------------------------- update
def update_drive(
    reference: Any,
    drive: Any,
    output: Any,
    *,
    fs: float,
    model: Any = None,
    inverse: InverseModel | None = None,
    state: IterationState | None = None,
    options: UpdateOptions | None = None,
) -> DriveUpdate:
    """One drive-file iteration from a measured run: ``u⁺ = u + L Q F (r − y)``.

    Parameters
    ----------
    reference, drive, output : array_like, shape (n_samples,)
        Desired output, the drive that was played and the measured output, about the
        operating point, sampled at ``fs``.
    fs : float
        Sample rate (Hz).
    model : ArmaxModel, optional
        The closed-loop model (needed for ``method="model"``; with ``"frf"`` it only
        supplies the default band).
    inverse : InverseModel, optional
        The inverse of ``model`` if already designed.
    state : IterationState, optional
        From the previous update: this run is compared with the one that update started
        from, and the update refused (gain halved) if the error grew.
    options : UpdateOptions, optional
        Inverse, band, gain and re-identification (default ``UpdateOptions()``).

    Returns
    -------
    DriveUpdate

    Raises
    ------
    TypeError
        For options or a state of the wrong type.
    ParameterError
        No band, no model for ``method="model"``, or a model error too large for any
        stable gain.
    """
    opts = or_default(options, UpdateOptions, "options")
    r, u, y = _same_length(reference, drive, output)
    if state is not None and not isinstance(state, IterationState):
        raise TypeError(f"state must be an IterationState, not {type(state).__name__}")
    record = run_record(r, u, y)
    if state is not None and record.rms_error >= state.base_rms_error:
        return _refused(state, record)
    band = opts.band_hz if opts.band_hz is not None or model is None else model.band_hz
    if band is None:
        raise ParameterError("the learning update needs a band (band_hz, or a model that "
                             "carries its validated band)")
    if opts.method == "model":
        used_model, inverse = _model_inverse(model, inverse, u, y, fs, band, opts)
        # the correction stays inside the band (Q-filter): nothing passes outside it
        correction = apply_inverse(inverse, r - y, fs, outside_band="zero")
        operator = inverse.frequency_response
    else:
        limited, cutoff = _band_and_cutoff(band, None, fs)
        assert limited is not None  # a band was given
        band = limited
        operator = _frf_inverse(u, y, fs, band, cutoff)
        # Q·γ²/Ĥ applied like the band limit: zero-phase, by FFT over a padded record
        correction = _fft_band_limit(r - y, 1.0 / fs, band, cutoff, shape=operator)
        used_model, inverse = None, None
    gain = opts.gain
    if gain is None:
        gain = state.gain if state is not None else learning_gain(u, y, fs, operator, band)
    # u_{k+1} = u_k + L Q F (r - y_k)
    new_drive = u + gain * correction
    nxt = IterationState(base_drive=u, correction=correction, gain=float(gain),
                         base_rms_error=record.rms_error, halvings=0)
    return DriveUpdate(drive=new_drive, record=record, accepted=True, stopped=False,
                       gain=float(gain), state=nxt, model=used_model, inverse=inverse,
                       message=f"update with gain {gain:g} (RMS error {record.rms_error:.4g})")


def _refused(state: IterationState, record: RunRecord) -> DriveUpdate:
    """The error grew: refuse the update, go back to the better drive, halve the gain
    (or stop after :data:`MAX_HALVINGS` halvings, handing back the best drive)."""
    halvings = state.halvings + 1
    if halvings > MAX_HALVINGS:
        return DriveUpdate(
            drive=state.base_drive.copy(), record=record, accepted=False, stopped=True,
            gain=0.0, state=state,
            message=(f"RMS error {record.rms_error:.4g} did not fall below "
                     f"{state.base_rms_error:.4g} after {MAX_HALVINGS} gain halvings: "
                     "iteration stopped, the best drive is handed back"))
    new_gain = 0.5 * state.gain
    nxt = IterationState(base_drive=state.base_drive, correction=state.correction,
                         gain=new_gain, base_rms_error=state.base_rms_error,
                         halvings=halvings)
    return DriveUpdate(
        drive=state.base_drive + new_gain * state.correction, record=record,
        accepted=False, stopped=False, gain=new_gain, state=nxt,
        message=(f"RMS error grew from {state.base_rms_error:.4g} to "
                 f"{record.rms_error:.4g}: update refused, gain halved to {new_gain:g}"))


def _model_inverse(model: Any, inverse: InverseModel | None, u: np.ndarray, y: np.ndarray,
                   fs: float, band: tuple[float, float], opts: UpdateOptions
                   ) -> tuple[Any, InverseModel]:
    """The model of a model-based update (re-identified from the run on request) and
    its inverse in the band."""
    if model is None and inverse is None:
        raise ParameterError("method='model' needs the model (or its inverse)")
    used_model = model
    if opts.reidentify:
        used_model, inverse = _reidentified(model, u, y, fs, band, opts, inverse)
    if inverse is None:
        inverse = design_inverse(model, method=opts.inverse_method, band_hz=band,
                                 known=opts.known)
    return used_model, inverse


def _reidentified(model: Any, u: np.ndarray, y: np.ndarray, fs: float,
                  band: tuple[float, float], opts: UpdateOptions,
                  inverse: InverseModel | None) -> tuple[Any, InverseModel | None]:
    """Model re-identified from the run (RML, the model's orders) and its inverse; the
    given model and inverse when the re-identification is unusable."""
    from dataclasses import replace

    from ehss.identification.estimators import estimate

    if model is None:
        raise ParameterError("reidentify needs the model (its orders and delay)")
    known, nc = opts.known, opts.nc
    na, nb = (model.na, model.nb) if opts.orders is None else opts.orders
    stored = model.meta.get("known_factors")
    if opts.orders is None and stored is not None:
        na, nb = na - (len(stored["den"]) - 1), nb - (len(stored["num"]) - 1)
        known = (np.asarray(stored["num"], float), np.asarray(stored["den"], float))
    q = rate_factor(fs, model.dt)
    if q > 1:  # the model is at a decimated rate: so must its data be
        u, y = decimate(u, y, q)
    u_id = u if known is None else scipy.signal.lfilter(known[0], known[1], u)
    try:
        new = estimate(u_id, y, method="rml", na=na, nb=nb,
                       nc=model.nc if nc is None else nc, delay=model.delay, dt=model.dt)
        new = replace(new, band_hz=band)
        return new, design_inverse(new, method=opts.inverse_method, band_hz=band,
                                   known=known)
    except ParameterError:
        return model, inverse  # an unusable re-identification (e.g. unstable)


# ------------------------------------------------------------------- checked iteration
def corrected_drive(
    model: Any,
    reference: Any,
    played: Any,
    measured: Any,
    *,
    fs: float,
    offsets: Any = "model",
    fade_s: float | None = None,
    force: bool = False,
    checks: dict[str, Any] | None = None,
    state: IterationState | None = None,
    options: UpdateOptions | None = None,
) -> tuple[Compensation, DriveUpdate]:
    """One drive-file iteration run as :func:`~ehss.compensation.apply.compensation` runs
    a one-shot drive: about the model's operating point, the reference faded and at rest,
    the next drive checked before it is returned.

    Parameters
    ----------
    model : ArmaxModel
        The closed-loop model (its ``offsets`` are the operating point by default).
    reference, played, measured : array_like, shape (n_samples,)
        Desired output, the drive that was played and the measured output, with their
        operating points, at ``fs``.
    fs : float
    offsets : "model", None or (u0, y0)
        As for :func:`~ehss.compensation.apply.compensation`.
    fade_s : float, optional
        Fade of the reference (about ``y0``), s.
    force : bool
        Keep a drive that fails its checks (``failed_check`` says which).
    checks : dict, optional
        ``max_gain``, ``min_gain``, ``limits``, ``loop``, ``params`` of
        :func:`~ehss.compensation.checks.check_drive`. When the iteration stopped and
        hands back the best drive (already played), the gain bounds are not applied again.
    state : IterationState, optional
        From the previous update (:func:`update_drive`).
    options : UpdateOptions, optional
        How the drive is corrected (:func:`update_drive`).

    Returns
    -------
    compensation : Compensation
        The next drive (``inverse`` is the update's model inverse, or None for
        ``method="frf"``).
    update : DriveUpdate
        The update's record, decision and state, about the operating point.

    Raises
    ------
    ParameterError
        As :func:`update_drive`, a reference not at rest, a drive that is not finite,
        or (without ``force``) one that fails its checks.
    """
    u0, y0 = model_offsets(model, offsets)
    r_dev = as_signal(reference, "reference") - y0
    if fade_s is not None:
        r_dev = fade_to_rest(r_dev, fs, fade_s)
    check_at_rest(r_dev)
    u = as_signal(played, "drive")
    y = as_signal(measured, "output")
    step = update_drive(r_dev, u - u0, y - y0, fs=fs, model=model, state=state,
                        options=options)
    checks = dict(checks or {})
    if step.stopped:
        checks.update(max_gain=None, min_gain=None)
    check, failure = checked_drive(step.drive, r_dev, fs, force=force, drive_offset=u0,
                                   **checks)
    result = Compensation(drive=u0 + step.drive, reference=r_dev + y0, fs=float(fs),
                          inverse=step.inverse, check=check, failed_check=failure,
                          warnings=(), offsets=(u0, y0), decimation=rate_factor(fs, model.dt))
    return result, step
