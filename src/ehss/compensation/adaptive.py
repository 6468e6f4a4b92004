"""Adaptive inverse-model compensation: the inverse of the online model, updated safely.

A rig identified online (:class:`ehss.RelsEstimator`) has, at any time, a model
``G = q^-d B/A`` of its closed loop. :func:`design_compensator` turns it into the
compensator a real-time target runs (:mod:`ehss.target.filter`): second-order sections,
an FIR part and an integer preview ``P``,

.. math:: C(q) = q^{P}\\, S(q^{-1})\\, H(q^{-1}),

with ``S = A / (k B_i)`` the exact inverse of the model's minimum-phase part (the
sections of :func:`ehss.compensation.design_inverse`'s causal filter) and ``H`` an FIR
of ``n_taps`` taps fitted by weighted least squares so that ``C`` matches, over the
whole frequency axis, the compensator that ``ehss compensate`` applies to a drive file:

.. math:: T(\\omega) = W(\\omega)\\, F(\\omega) + (1 - W(\\omega)),

the exact stable inverse ``F`` inside the band limit ``W`` (the band the model is
validated over), the reference itself outside it. The FIR carries everything that is
not causal and minimum phase: the delay's advance ``q^d``, the anti-causal inverse of
the non-minimum-phase zeros, the zeros near the unit circle and the band limit.

Two reference modes:

* **preview** (the reference is known ahead, a drive file streamed): ``P`` samples of
  it are known, and the FIR spans ``P`` samples of the future. The fit is then exact
  up to what the anti-causal part leaves beyond ``P`` samples (its error is reported).
* **causal** (the reference is made online, ``P = 0``): the same fit with a causal FIR,
  i.e. the least-squares causal predictor of the exact inverse over the band. It leaves
  amplitude and phase errors, reported per design (:attr:`CompensatorDesign.errors`).

:class:`AdaptiveCompensator` decides whether a new design may replace the running one
(:class:`UpdateGuard`): the model must be stable, pass its band in phase at the low edge
(a closed loop that tracks does), agree with the sliding H1 estimate over the band as
:class:`ehss.workflow.Acceptance` asks (errors beyond the estimate's own standard error
within 1 dB and 5°), be realised by the target's filter well enough in preview mode that
the loop tracks better with it than without (a preview far too short for the loop at
its rate is not; one short enough to miss the H1 bounds is said so), and give, for the
recent reference, a drive that the gain checks and the rig's limits of ``ehss compensate``
accept (:func:`ehss.compensation.check_drive`), and fit the newest quarter-second of
feedback (fresh data, the free-run fit that
:class:`~ehss.workflow.Acceptance` asks of a validated model).
Otherwise the last good compensator stays and the reason is logged. Updates are at most
one per ``min_interval_s``.

After a change of the rig, before a full model of the new loop can be trusted, the
running compensator can be *corrected* (preview mode): :func:`fit_correction` fits a
short non-causal FIR ``K`` with ``L K ≈ 1`` to the data since the change (``L`` the
loop as compensated now), :func:`fold_correction` refits the FIR part to ``C K``, and
:meth:`AdaptiveCompensator.assess_correction` guards it (checked on fresh data, its
gain and phase bounded, the drive checks).

References: eqs (16)–(22) of the paper (the model and its recursive estimate).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np
import scipy.linalg
import scipy.signal

from ehss._checks import check_int, check_real
from ehss._settle import settle_samples
from ehss.compensation.checks import DEFAULT_MAX_GAIN, DriveLimits, check_drive
from ehss.compensation.inverse import InverseModel, design_inverse
from ehss.errors import DataError, EhssError, ParameterError
from ehss.identification.model import ArmaxModel
from ehss.validation import frf_error
from ehss.workflow import Acceptance

__all__ = [
    "MODES",
    "H1_DISAGREES",
    "CompensatorDesign",
    "UpdateGuard",
    "Decision",
    "AdaptiveCompensator",
    "design_compensator",
    "run_compensator",
    "free_run_fit",
    "Correction",
    "fit_correction",
    "fold_correction",
    "ErrorComparison",
    "compare_compensators",
    "KeptRunning",
]

#: Reference modes: known ahead (a drive file streamed) or made online.
MODES = ("preview", "causal")
#: How a refusal for the model's disagreement with the H1 estimate begins.
H1_DISAGREES = "the model disagrees with the H1 estimate"

#: Weights of the fit (inside the band, in the band limit's transitions, outside its
#: support), per mode: the squared error at each frequency counts by the reference's
#: power there. Preview: the exact inverse in the band, and 1 % (20 dB down, the edge of
#: the reference's band, :func:`ehss.live.reference_band`) in the transitions and
#: outside. A transition narrower than the FIR's resolution (fs / n_taps: 0.25 Hz wide
#: at a 0.5 Hz edge, against 4 Hz for 256 taps at 1 kHz) cannot be realised; weighed
#: like the band it took taps from the band's fit (0.09–0.19 dB / 0.4–1.1° there on the
#: simulated rig, 0.10–0.21 dB / 0.3–0.5° weighed at 1 %). Causal:
#: the fit is the least-squares causal *prediction* of the exact inverse for a reference
#: that has its power in the band: 30 dB down in the transitions, 60 dB outside (a
#: band-limited reference); it buys its accuracy in the band with gain outside it
#: (:attr:`CompensatorDesign.peak_gain`), which the drive checks bound.
_WEIGHTS = {"preview": (1.0, 1e-2, 1e-2), "causal": (1.0, 1e-3, 1e-6)}


@dataclass(frozen=True, kw_only=True)
class CompensatorDesign:
    """A compensator as a target runs it, and what it costs against the exact inverse.

    Attributes
    ----------
    sos : ndarray, shape (n_sections, 6)
        Second-order sections (scipy's layout), ``S = A/(k B_i)`` (the zeros of ``B_i``
        whose modes outlast an eighth of the FIR are left to the FIR, unless the band
        reaches down to them: :func:`design_compensator`).
    taps : ndarray, shape (n_taps,)
        FIR part after the sections.
    preview : int
        Samples of reference the filter's input runs ahead of the drive.
    fs_hz : float
    mode : {"preview", "causal"}
    band_hz : (float, float)
        Band the model is trusted over (the inverse's band limit).
    inverse : InverseModel
        The exact stable inverse it realises (:func:`design_inverse`).
    freq_hz : ndarray
        Grid over the band where the errors were computed.
    error : ndarray, complex
        ``C / T - 1`` on that grid: the relative error against the exact inverse (what
        the loop's response differs from 1 by, if the model is right).
    peak_gain : float
        Largest ``|C|`` from 0 to fs/2 (what the compensator can amplify).
    settle_samples : int
        Samples the filter needs to forget its start (sections' slowest mode, FIR span:
        :func:`ehss._settle.settle_samples`, the rule the target's filter applies too).
    """

    sos: np.ndarray = field(repr=False)
    taps: np.ndarray = field(repr=False)
    preview: int
    fs_hz: float
    mode: str
    band_hz: tuple[float, float]
    inverse: InverseModel = field(repr=False)
    freq_hz: np.ndarray = field(repr=False)
    error: np.ndarray = field(repr=False)
    peak_gain: float
    settle_samples: int

    @property
    def max_amplitude_error_db(self) -> float:
        """Largest ``|20 log10 |C/T||`` over the band, dB."""
        return float(np.max(np.abs(20.0 * np.log10(np.abs(1.0 + self.error)))))

    @property
    def max_phase_error_deg(self) -> float:
        """Largest ``|arg(C/T)|`` over the band, degrees."""
        return float(np.max(np.abs(np.degrees(np.angle(1.0 + self.error)))))

    def frequency_response(self, freq_hz: Any) -> np.ndarray:
        """Complex response ``C(e^{jω})`` of the compensator at ``freq_hz``."""
        return _realised(self.sos, self.taps, self.preview,
                         np.asarray(freq_hz, dtype=float) / self.fs_hz)

    def errors(self) -> dict[str, float]:
        """JSON-ready figures: max amplitude (dB) and phase (degrees) error over the band,
        and the RMS relative error."""
        return {"max_amplitude_error_db": self.max_amplitude_error_db,
                "max_phase_error_deg": self.max_phase_error_deg,
                "peak_gain": self.peak_gain,
                "rms_relative_error": float(np.sqrt(np.mean(np.abs(self.error) ** 2)))}


def _sections(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    """``num/den`` (ascending powers of q^-1) as second-order sections."""
    n = max(num.size, den.size)
    b = np.zeros(n)
    a = np.zeros(n)
    b[:num.size] = num
    a[:den.size] = den
    if n == 1:
        return np.array([[b[0] / a[0], 0.0, 0.0, 1.0, 0.0, 0.0]])
    return np.ascontiguousarray(scipy.signal.tf2sos(b, a))


def _fast_part(den: np.ndarray, n_taps: int, slowest: float = 0.0) -> np.ndarray:
    """The factor of ``den`` (monic, roots inside the unit circle) whose modes die out
    within an eighth of the FIR's span, or whose radius is at most ``slowest``; the
    slower ones are left to the FIR's fit.

    A zero of the model close to ``z = 1`` gives the inverse a mode of seconds; run as a
    section it would need seconds in shadow before each update could be faded in. Where
    its effect lies below the band, the target there is the reference itself and the FIR
    fits it; where it reaches into the band, only a section realises it
    (:func:`design_compensator`).
    """
    roots = np.roots(den) if den.size > 1 else np.zeros(0, complex)
    fast = roots[np.abs(roots) <= max(math.exp(-8.0 / n_taps), slowest)]
    return np.real_if_close(np.poly(fast), tol=1e6).real if fast.size else np.ones(1)


def _slowest_section(fs: float, lo: float) -> float:
    """Radius of the slowest mode a section may take when the FIR cannot realise it:
    one whose corner is a quarter of the band's lower edge (its settling, seven time
    constants, is then ``4.46 / lo`` s: 4.5 s for a band from 1 Hz). A slower mode acts
    in the band as an integrator whatever its radius, and would hold every update in
    shadow longer than a loop's change takes to follow. 0 (none) for a band from DC."""
    return math.exp(-2.0 * math.pi * (lo / 4.0) / fs) if lo > 0 else 0.0


def _rms_error(design: CompensatorDesign) -> float:
    return float(np.sqrt(np.mean(np.abs(design.error) ** 2)))


def _sos_response(sos: np.ndarray, w: np.ndarray) -> np.ndarray:
    h = np.ones(w.shape, complex)
    x = np.exp(-1j * w)
    for b0, b1, b2, a0, a1, a2 in sos:
        h *= (b0 + b1 * x + b2 * x * x) / (a0 + a1 * x + a2 * x * x)
    return h


def _realised(sos: np.ndarray, taps: np.ndarray, preview: int, f_norm: np.ndarray
              ) -> np.ndarray:
    """``e^{jωP} S(ω) H(ω)`` at normalised frequencies ``f/fs``."""
    w = 2.0 * np.pi * f_norm
    fir = np.exp(-1j * np.outer(w, np.arange(taps.size))) @ taps
    return np.exp(1j * w * preview) * _sos_response(sos, w) * fir


def _fit_taps(s_resp: np.ndarray, target: np.ndarray, weight: np.ndarray, preview: int,
              n_taps: int) -> np.ndarray:
    """Weighted least squares: ``min sum weight |e^{jωP} S H - T|^2`` over real taps.

    On the uniform grid ``ω_k = π k / K`` (k = 0..K) with the FIR's columns
    ``e^{jω(P-j)} S(ω)``, the normal equations' matrix is Toeplitz,
    ``R[i, j] = sum weight |S|^2 cos(ω (i - j))``, and the right-hand side
    ``b[j] = sum weight Re(conj(S) T e^{jω(j-P)})``: both are inverse FFTs of length 2K,
    and Levinson's recursion solves the equations in O(n_taps^2).
    """
    k = s_resp.size - 1
    c = weight * np.abs(s_resp) ** 2
    r = np.fft.ifft(np.concatenate([c, np.zeros(k - 1)])).real[:n_taps]
    g = weight * np.conj(s_resp) * target
    lag = (np.arange(n_taps) - preview) % (2 * k)
    b = np.fft.ifft(np.concatenate([g, np.zeros(k - 1)]))[lag].real
    # a relative 1e-10 on the diagonal: the taps stay bounded where the weight is small
    r[0] *= 1.0 + 1e-10
    return scipy.linalg.solve_toeplitz(r, b)


def _grid_size(fs: float, band: tuple[float, float], n_taps: int) -> int:
    """K of the grid ``f_k = k fs / (2K)``: 16 points per tap, and 8 across the band
    limit's lower transition (``lo/2`` wide), but no more than 64 per tap.

    The FIR part resolves no detail finer than ``fs / n_taps``; 64 grid points per tap
    sample the weighted error it is fitted to well below that. A finer grid changes the
    fit by nothing the filter can realise and costs its size in every FFT (2**17 points,
    about 60 ms a design at 5 kHz, where the cap gives 2**14).
    """
    lo = band[0] if band[0] > 0 else band[1]
    want = min(max(16 * n_taps, 8.0 * fs / lo), 64 * n_taps)
    return int(2 ** math.ceil(math.log2(want)))


def design_compensator(model: ArmaxModel, *, band_hz: tuple[float, float] | None = None,
                       mode: str = "preview", preview: int | None = None,
                       n_taps: int = 256, max_sections: int = 16,
                       within: tuple[float, float] = (1.0, 5.0)) -> CompensatorDesign:
    """The compensator of ``model`` as sections, an FIR part and a preview.

    Parameters
    ----------
    model : ArmaxModel
        Closed-loop model (reference → feedback), e.g. ``RelsEstimator.model``.
    band_hz : (lo, hi), optional
        Band the model is trusted over (default ``model.band_hz``; one is needed).
    mode : {"preview", "causal"}
    preview : int, optional
        Samples known ahead in preview mode (default ``n_taps // 2``); must be 0 or
        absent in causal mode.
    n_taps : int
        FIR length (the target's limit, e.g. 256).
    max_sections : int
        Most second-order sections the target runs.
    within : (dB, degrees)
        How closely the filter must realise the inverse over the band before its slow
        modes are tried as sections (default the bounds a model must meet against the
        H1 estimate, :class:`ehss.workflow.Acceptance`). The inverse's modes that
        outlast an eighth of the FIR are left to the FIR, which fits them below the
        band; where the band reaches down to them (a loop with a high-pass near its
        lower edge: an AC-coupled sensor, a shaking table's acceleration generator)
        the FIR cannot, and the modes no slower than a quarter of the band's lower
        edge are run as sections instead, if that realises the inverse better: each
        update then settles longer in shadow (:attr:`CompensatorDesign.settle_samples`,
        up to ``4.46 / lo`` s).

    Returns
    -------
    CompensatorDesign

    Raises
    ------
    ParameterError
        No band, a bad mode, preview or size, or a model that cannot be inverted
        (:func:`ehss.compensation.design_inverse`: unstable, zero on the unit circle in
        the band).

    Examples
    --------
    >>> from ehss.identification.model import ArmaxModel
    >>> m = ArmaxModel(a=[1.0, -0.9], b=[0.1], delay=1, dt=1e-3)
    >>> d = design_compensator(m, band_hz=(1.0, 50.0), n_taps=64)
    >>> d.preview, d.max_amplitude_error_db < 0.01
    (32, True)
    """
    if not isinstance(model, ArmaxModel):
        raise TypeError(f"model must be an ArmaxModel, not {type(model).__name__}")
    if mode not in MODES:
        raise ParameterError(f"mode={mode!r} must be one of {MODES}")
    n_taps = check_int(n_taps, "n_taps", lo=1)
    preview = _check_preview(mode, preview, n_taps)
    within = _check_within(within)
    band = band_hz if band_hz is not None else model.band_hz
    if band is None:
        raise ParameterError("the compensator needs the band the model is trusted over: "
                             "give band_hz (or a model with one)")
    inv = design_inverse(model, band_hz=band)
    # the band the inverse was limited to (it was given one)
    inv_band = inv.band_hz if inv.band_hz is not None else (float(band[0]), float(band[1]))
    # the modes the FIR takes first; if it then misses ``within``, those of them that
    # reach into the band go to the sections as well, if that realises the inverse better
    fast = _fast_part(inv.den, n_taps)
    more = _fast_part(inv.den, n_taps, _slowest_section(model.fs, inv_band[0]))
    design = None
    for den in (fast, more) if more.size > fast.size else (fast,):
        sos = _sections(inv.num, den)
        if sos.shape[0] > max_sections:
            raise ParameterError(f"the inverse needs {sos.shape[0]} second-order sections, "
                                 f"the target runs {max_sections}; identify a lower order")
        got = _realise(sos, inv, inv_band, fs_hz=model.fs, mode=mode, preview=preview,
                       n_taps=n_taps)
        if design is None or _rms_error(got) < _rms_error(design):
            design = got
        if design.max_amplitude_error_db <= within[0] \
                and design.max_phase_error_deg <= within[1]:
            break
    assert design is not None
    return design


def _realise(sos: np.ndarray, inv: InverseModel, band: tuple[float, float], *,
             fs_hz: float, mode: str, preview: int, n_taps: int,
             correction: tuple[CompensatorDesign, Correction] | None = None
             ) -> CompensatorDesign:
    """The FIR after ``sos`` fitted to ``T = W F + (1 - W)``; with ``correction``
    (the running design, of the same sections, and a correction ``K``) to the running
    design's own response times ``W K + (1 - W)`` (:func:`fold_correction`)."""
    lo, hi = band
    k = _grid_size(fs_hz, band, n_taps)
    f = np.arange(k + 1) * (0.5 * fs_hz / k)
    w = np.pi * np.arange(k + 1) / k
    band_w = inv.band_response(f)
    s_resp = _sos_response(sos, w)
    if correction is None:
        # T = W F + (1 - W): the exact inverse in the band, the reference outside it
        target = inv.frequency_response(f, band=True) + (1.0 - band_w)
    else:
        running, kappa = correction
        # T = C_run (W K + (1 - W)): the correction in the band, nothing outside it
        c_run = np.exp(1j * w * preview) * s_resp * np.fft.rfft(running.taps, 2 * k)
        target = c_run * (band_w * kappa.frequency_response(f) + (1.0 - band_w))
    w_in, w_edge, w_out = _WEIGHTS[mode]
    weight = np.where(band_w >= 1.0, w_in, np.where(band_w > 0.0, w_edge, w_out))
    taps = _fit_taps(s_resp, target, weight, preview, n_taps)
    # C = e^{jωP} S H on the grid
    got = np.exp(1j * w * preview) * s_resp * np.fft.rfft(taps, 2 * k)
    inside = (f >= lo) & (f <= hi)
    return CompensatorDesign(
        sos=sos, taps=np.ascontiguousarray(taps), preview=int(preview), fs_hz=float(fs_hz),
        mode=mode, band_hz=(float(lo), float(hi)), inverse=inv, freq_hz=f[inside],
        error=got[inside] / target[inside] - 1.0, peak_gain=float(np.max(np.abs(got))),
        settle_samples=settle_samples(sos, taps.size),
    )


def _check_within(within: Any) -> tuple[float, float]:
    """``within`` as (dB, degrees), each positive (inf: no bound)."""
    try:
        db, deg = within
    except (TypeError, ValueError):
        raise ParameterError(f"within={within!r} must be a pair (dB, degrees)") from None
    return (db if db == math.inf else check_real(db, "within dB", lo=0.0, lo_open=True),
            deg if deg == math.inf else check_real(deg, "within degrees", lo=0.0,
                                                   lo_open=True))


def _check_preview(mode: str, preview: Any, n_taps: int) -> int:
    if mode == "causal":
        if preview not in (None, 0):
            raise ParameterError(f"preview={preview!r}: the causal mode has none (0)")
        return 0
    if preview is None:
        return n_taps // 2
    return check_int(preview, "preview", lo=0, hi=n_taps - 1)


def run_compensator(design: CompensatorDesign, reference: Any) -> np.ndarray:
    """The drive ``design`` gives for ``reference`` over a record, started at rest.

    ``u[k] = (h * S r)[k + P]``: the same sections and FIR the target runs, with the
    reference known to the record's end (held at its last value beyond it).

    Parameters
    ----------
    design : CompensatorDesign
    reference : array_like, shape (n,)

    Returns
    -------
    ndarray, shape (n,)
    """
    r = np.asarray(reference, dtype=float)
    p = design.preview
    x = np.concatenate([r[p:], np.full(min(p, r.size), r[-1] if r.size else 0.0)])
    v = scipy.signal.sosfilt(design.sos, x)
    return scipy.signal.lfilter(design.taps, [1.0], v)


def free_run_fit(model: ArmaxModel, u: Any, y: Any, n_fit: int) -> float:
    """Fit (%) of ``model`` simulated in free run on the drive ``u`` to the latest
    ``n_fit`` samples of the feedback ``y``: 100 (1 − |y − ŷ| / |y − mean y|), as
    :mod:`ehss.validation` computes it (−inf when those samples do not vary, or the
    model is unstable or its simulation overflows: nothing to judge).

    Parameters
    ----------
    model : ArmaxModel
    u, y : array_like, shape (n,)
    n_fit : int
        Samples at the end of the record judged (the simulation runs over all of it,
        so that its start-up has died out).

    Returns
    -------
    float
    """
    y = np.asarray(y, dtype=float)
    y_run = _free_run(model, u)
    if y_run is None:
        return -math.inf
    with np.errstate(over="ignore", invalid="ignore"):
        y_new = y[-n_fit:]
        spread = float(np.linalg.norm(y_new - np.mean(y_new)))
        miss = float(np.linalg.norm(y_new - y_run[-n_fit:]))
    if not (spread > 0.0 and math.isfinite(miss)):
        return -math.inf
    return 100.0 * (1.0 - miss / spread)


def _free_run(model: ArmaxModel, u: Any) -> np.ndarray | None:
    """``model``'s deterministic part run from rest on ``u`` (None if it is unstable)."""
    if not model.is_stable():
        return None
    b = np.concatenate([np.zeros(model.delay), model.b])
    with np.errstate(over="ignore", invalid="ignore"):
        return np.asarray(scipy.signal.lfilter(b, model.a, np.asarray(u, dtype=float)))


# ---------------------------------------------------------------------- correction
#: A correction must leave at most this share of the tracking error on the samples it
#: was not fitted to: the changes it is for raise the error 4–9× (README), while noise
#: as large as the reference in the band (a burst of sensor noise) fitted the same way
#: leaves 1/√2 of it.
CORRECTION_MAX_RATIO = 0.5
#: Bounds of a correction's gain and phase over the band. ``|1 - L| = 1``, a loop whose
#: error is as large as its reference, lies at a phase of 60° for a gain of 1 and at a
#: gain of 1/2 or 2 in phase: a correction beyond ±60° or outside [1/3, 3] would follow a
#: loop that no longer tracks (a feedback flipped gives ``K = -1``, a stuck sensor an
#: unbounded one), not a change of one that does.
CORRECTION_GAIN = (1.0 / 3.0, 3.0)
CORRECTION_PHASE_DEG = 60.0


@dataclass(frozen=True, kw_only=True)
class Correction:
    """A short non-causal FIR ``K`` that corrects the running compensator after a change.

    With the running compensator ``C`` the loop from the desired reference ``r`` to the
    feedback ``y`` is ``L = G C``; when the rig changes, ``L`` moves away from 1. The
    correction is the least-squares ``K`` with ``r ≈ K y``,

    .. math:: r[k] \\approx \\sum_{j=-m}^{m} \\kappa_j\\, y[k + j],

    so that ``L K ≈ 1`` in the band, and the compensator ``C K`` takes the loop back
    (:func:`fold_correction`). Five taps (``m = 2``) span a gain, a lead and a second
    derivative, as the adaptive time-series compensator of Chae et al. (2013) does.

    Attributes
    ----------
    taps : ndarray, shape (2 m + 1,)
        ``κ_{-m} .. κ_m``.
    fs_hz : float
    band_hz : (float, float)
    n_fit, n_check : int
        Samples it was fitted on, and the newer ones it was checked on.
    check_ratio : float
        RMS of the band-limited ``r − K y`` over that of ``r − y`` on the check samples
        (of ``K_then r − K y`` over ``K_then r − K_then y`` under an earlier correction
        ``K_then``): the tracking error it leaves of the one that runs, on data it was
        not fitted to.
    check_residual : float
        RMS of that error over the reference's (``r`` or ``K_then r``) there.
    refines : bool
        Whether it replaces an earlier correction (fitted on data under one).
    gain_range : (float, float)
        Least and largest ``|K|`` over the band.
    max_phase_deg : float
        Largest ``|arg K|`` over the band.
    """

    taps: np.ndarray = field(repr=False)
    fs_hz: float
    band_hz: tuple[float, float]
    n_fit: int
    n_check: int
    check_ratio: float
    check_residual: float
    refines: bool
    gain_range: tuple[float, float]
    max_phase_deg: float

    def frequency_response(self, freq_hz: Any) -> np.ndarray:
        """``K(e^{jω}) = Σ κ_j e^{jωj}`` at ``freq_hz``."""
        m = (self.taps.size - 1) // 2
        w = 2.0 * np.pi * np.asarray(freq_hz, dtype=float) / self.fs_hz
        return np.exp(1j * np.outer(w, np.arange(-m, m + 1))) @ self.taps

    def figures(self) -> dict[str, Any]:
        """JSON-ready: its taps and what it was judged on."""
        return {"correction_taps": [float(v) for v in self.taps], "n_fit": self.n_fit,
                "check_ratio": self.check_ratio, "check_residual": self.check_residual,
                "refines": self.refines, "gain_range": list(self.gain_range),
                "max_phase_deg": self.max_phase_deg}


def _band_limited(x: np.ndarray, fs_hz: float, band: tuple[float, float]) -> np.ndarray:
    """``x`` through a zero-phase 4th-order Butterworth low-pass at the band's upper edge,
    its mean removed: the same filter on ``r`` and ``y`` keeps ``r ≈ K y``, and noise
    above the band does not enter the fit."""
    sos = scipy.signal.butter(4, band[1], fs=fs_hz, output="sos")
    return scipy.signal.sosfiltfilt(sos, x - np.mean(x))


def fit_correction(desired: Any, feedback: Any, *, fs_hz: float, band_hz: tuple[float, float],
                   spans: Any, n_check: int, half_span: int = 2,
                   base: CompensatorDesign | None = None) -> Correction:
    """The correction ``K`` of a record's spans since a change.

    Parameters
    ----------
    desired, feedback : array_like, shape (n,)
        ``r`` and ``y`` (older samples may precede the change: only the rows of
        ``spans`` enter the fit, the rest only feed the band limit's filter).
    fs_hz : float
    band_hz : (lo, hi)
    spans : sequence of (start, stop, then)
        Index ranges of the record, oldest first, each run by one compensator: ``base``,
        the one ``K`` corrects (``then`` None), or ``base`` corrected by the taps
        ``then`` of an earlier correction, or another compensator ``then`` (a
        :class:`CompensatorDesign`), whose rows then ask ``K y`` to give
        ``K_then r`` or ``(C_then / C_base) r`` (so that the rows of every span fit the
        same ``K``, the whole correction of ``base``). The last span is run by ``base``
        or a correction of it.
    n_check : int
        The newest rows (of the last span) ``K`` is checked on, not fitted to
        (:attr:`Correction.check_ratio`); the samples of the last period of the band's
        upper edge are left out (the zero-phase filter's end is not settled there).
    half_span : int
        ``m``: the taps run from ``-m`` to ``m``.
    base : CompensatorDesign, optional
        Needed when a span was run by another compensator.

    Returns
    -------
    Correction

    Raises
    ------
    DataError
        Too few rows for the taps, or a feedback that does not vary.
    """
    r = np.asarray(desired, dtype=float)
    y = np.asarray(feedback, dtype=float)
    m = check_int(half_span, "half_span", lo=0)
    edge = int(math.ceil(fs_hz / band_hz[1]))
    rf = _band_limited(r, fs_hz, band_hz)
    yf = _band_limited(y, fs_hz, band_hz)
    shifts = range(-m, m + 1)
    identity = np.zeros(2 * m + 1)
    identity[m] = 1.0
    parts: list[tuple[np.ndarray, np.ndarray]] = []
    wants: list[np.ndarray] = []
    for start, stop, then in spans:
        rows = np.arange(max(int(start), m), min(int(stop), r.size - max(edge, m)))
        if not rows.size:
            continue
        if isinstance(then, CompensatorDesign):
            if base is None:
                raise ParameterError("a span run by another compensator needs the base")
            # (C_then / C_base) r, over the band
            wants.append(_through(rf, then, base)[rows])
            k_then = identity
        else:
            k_then = identity if then is None else np.asarray(then, dtype=float)
            # r, or r through the correction that ran then
            wants.append(np.column_stack([rf[rows + j] for j in shifts]) @ k_then)
        parts.append((rows, k_then))
    if not parts:
        raise DataError("no samples to fit a correction on")
    ymat = np.vstack([np.column_stack([yf[rows + j] for j in shifts]) for rows, _ in parts])
    want = np.concatenate(wants)
    n_fit = want.size - int(n_check)
    if n_fit < 4 * (2 * m + 1) or n_check < 1:
        raise DataError(f"{n_fit} samples to fit {2 * m + 1} taps: too few")
    kappa, *_ = np.linalg.lstsq(ymat[:n_fit], want[:n_fit], rcond=None)
    if not np.all(np.isfinite(kappa)) or not np.any(ymat[:n_fit]):
        raise DataError("the feedback does not vary: no correction can be fitted")
    miss = want[n_fit:] - ymat[n_fit:] @ kappa
    was = want[n_fit:] - ymat[n_fit:] @ parts[-1][1]
    level = float(np.linalg.norm(want[n_fit:]))
    # (a loop without error leaves nothing to correct: measured against rounding then)
    ratio = float(np.linalg.norm(miss) / max(float(np.linalg.norm(was)), 1e-12 * level,
                                             1e-300))
    corr = Correction(taps=kappa, fs_hz=float(fs_hz), band_hz=band_hz, n_fit=n_fit,
                      n_check=int(n_check), check_ratio=ratio,
                      check_residual=float(np.linalg.norm(miss) / max(level, 1e-300)),
                      refines=any(isinstance(t, np.ndarray) for _, _, t in spans),
                      gain_range=(0.0, 0.0), max_phase_deg=0.0)
    k = corr.frequency_response(np.linspace(band_hz[0], band_hz[1], 64))
    return dataclasses.replace(corr, gain_range=(float(np.min(np.abs(k))),
                                                 float(np.max(np.abs(k)))),
                               max_phase_deg=float(np.max(np.abs(np.degrees(np.angle(k))))))


def _through(x: np.ndarray, then: CompensatorDesign, base: CompensatorDesign) -> np.ndarray:
    """``x`` (band-limited) through ``C_then / C_base``, by FFT over the record padded to
    twice its length (the rows it is taken at lie away from its ends)."""
    n_fft = 1 << int(math.ceil(math.log2(max(2 * x.size, then.taps.size, base.taps.size))))
    ratio = _on_grid(then, n_fft) / _on_grid(base, n_fft)
    return np.fft.irfft(np.fft.rfft(x, n_fft) * ratio, n_fft)[:x.size]


def _on_grid(design: CompensatorDesign, n_fft: int) -> np.ndarray:
    """:meth:`CompensatorDesign.frequency_response` at the ``n_fft // 2 + 1`` frequencies
    of a real FFT of ``n_fft`` points, the FIR's part by that FFT (O(n log n) instead
    of a sum over the taps at each frequency)."""
    w = 2.0 * np.pi * np.arange(n_fft // 2 + 1) / n_fft
    fir = np.fft.rfft(design.taps, n_fft)
    return np.exp(1j * w * design.preview) * _sos_response(design.sos, w) * fir


@dataclass(frozen=True)
class ErrorComparison:
    """Tracking error a new compensator would have left on recorded rows, against the
    running one's (:func:`compare_compensators`).

    Attributes
    ----------
    ratio : float
        RMS error of the new one over the running one's (band-limited; NaN: no rows).
    standard_error : float
        The ratio's standard error, from its spread over stretches of ``chunk``
        samples taken as independent (inf: fewer than two stretches). Errors that lie
        near the band's lower edge stay correlated over longer stretches: there it
        understates the ratio's scatter from one reference to another (1.5–6× over
        40 references of 1.5 s at 0.5–20 Hz, stretches of 0.1 s).
    rows : int
    """

    ratio: float
    standard_error: float
    rows: int


def _ratio_spread(e_new: np.ndarray, e_run: np.ndarray, chunk: int) -> tuple[float, float]:
    """sqrt(Σ e_new² / Σ e_run²) and its standard error by the delta method over
    stretches of ``chunk`` rows (each stretch's sums a paired sample)."""
    q = float(np.sum(e_new ** 2) / max(float(np.sum(e_run ** 2)), 1e-300))
    n = e_new.size // max(1, chunk)
    if n < 2:
        return math.sqrt(q), math.inf
    a = np.array([np.sum(p ** 2) for p in np.array_split(e_new, n)])
    b = np.array([np.sum(p ** 2) for p in np.array_split(e_run, n)])
    se_q = math.sqrt(float(np.sum((a - q * b) ** 2)) / (n * (n - 1))) / max(float(b.mean()),
                                                                         1e-300)
    return math.sqrt(q), se_q / (2.0 * math.sqrt(max(q, 1e-300)))


def compare_compensators(new: CompensatorDesign, running: CompensatorDesign, desired: Any,
                         feedback: Any, spans: Any, *, chunk: int) -> ErrorComparison:
    """The tracking error ``new`` would have left over ``spans`` of a record, against
    the error ``running`` left or would have left there (both band-limited).

    ``spans``: ``(start, stop, then)`` index ranges, each run by one compensator
    (``then``; None: ``running``). Where ``then`` ran, the feedback ``y = G C_then r``
    would have been ``(C / C_then) y`` under a compensator ``C``: the running one's
    own rows are taken as they are, the others' predicted so, and ``new``'s everywhere.
    The newest ``new.preview`` samples (and a period of the band's upper edge) are left
    out: the ratio looks that far ahead in ``y``, which is not known there.
    """
    band, fs = running.band_hz, running.fs_hz
    r = _band_limited(np.asarray(desired, dtype=float), fs, band)
    y = _band_limited(np.asarray(feedback, dtype=float), fs, band)
    end = r.size - max(new.preview, int(math.ceil(fs / band[1])))
    e_new: list[np.ndarray] = []
    e_run: list[np.ndarray] = []
    for start, stop, then in spans:
        rows = slice(int(start), min(int(stop), end))
        if rows.stop - rows.start < 1:
            continue
        then = running if then is None else then
        y_run = y if then is running else _through(y, running, then)
        e_run.append(r[rows] - y_run[rows])
        e_new.append(r[rows] - _through(y, new, then)[rows])
    if not e_new:
        return ErrorComparison(math.nan, math.inf, 0)
    ratio, se = _ratio_spread(np.concatenate(e_new), np.concatenate(e_run), chunk)
    return ErrorComparison(ratio, se, int(sum(e.size for e in e_new)))


def fold_correction(design: CompensatorDesign, correction: Correction) -> CompensatorDesign:
    """The compensator ``C K``: ``design``'s sections, its FIR refitted so that the whole
    matches ``C`` times ``K`` in the band and ``C`` outside it.

    The target runs it as any other compensator (same sections, preview and sizes).
    ``error`` of the result is against ``C K``. Preview mode only: ``K`` looks ``m``
    samples ahead, which the FIR's preview holds.

    Raises
    ------
    ParameterError
        A causal design (``K`` needs the reference ahead).
    """
    if design.mode != "preview" or design.preview < (correction.taps.size - 1) // 2:
        raise ParameterError("a correction looks ahead: it needs a compensator in "
                             "preview mode")
    return _realise(design.sos, design.inverse, design.band_hz, fs_hz=design.fs_hz,
                    mode=design.mode, preview=design.preview, n_taps=design.taps.size,
                    correction=(design, correction))


# --------------------------------------------------------------------------- guard
@dataclass(frozen=True, kw_only=True)
class UpdateGuard:
    """When a new compensator may replace the running one.

    Attributes
    ----------
    acceptance : Acceptance
        Agreement of the model with the sliding H1 estimate over the band, judged as a
        validated model is (:class:`ehss.workflow.Acceptance`: the errors beyond
        ``uncertainty_sigmas`` standard errors of the estimate within
        ``max_magnitude_db`` and ``max_phase_deg`` at ``min_frf_points`` or more coherent
        points).
    max_gain : float or None
        Drive-to-reference RMS and peak bound (:data:`DEFAULT_MAX_GAIN`).
    limits : DriveLimits, optional
        Explicit bounds of the drive.
    min_interval_s : float
        Fewest seconds between two updates of a channel.
    crossfade_s : float
        Length of the cross-fade from the old compensator to the new, s.
    fit_s : float
        Length of the newest stretch of feedback the model must fit (fresh data), s.
    """

    acceptance: Acceptance = field(default_factory=Acceptance)
    max_gain: float | None = DEFAULT_MAX_GAIN
    limits: DriveLimits | None = None
    min_interval_s: float = 0.5
    crossfade_s: float = 0.1
    fit_s: float = 0.25

    def __post_init__(self) -> None:
        for name in ("min_interval_s", "crossfade_s", "fit_s"):
            check_real(getattr(self, name), name, lo=0.0, unit="s")


#: A model refused for disagreeing with the H1 estimate by at most this many times the
#: acceptance's bounds (beyond the estimate's uncertainty) is a near miss, not a fault
#: (``Decision.fault`` False): the recursive estimate scatters around the loop, and a
#: healthy loop's refusals lie there. Measured against bounds of 1 dB / 5°: the
#: simulated rig, 60 s on two channels, 6 of 159 judgements refused, by at most
#: 0.25 dB / 6.9°; a 12 Hz loop over UDP, up to 1.64 dB / 9.4° while following a payload
#: change. A fault puts the model far off (a feedback sign flipped: 14 dB / 167°) or
#: fails another guard (unstable, too few coherent points, a poor fit to fresh data).
NEAR_MISS = 2.0
#: How many of the H1 estimate's points a single sinusoid fills, seen through the
#: estimate's Hann window: the participation ratio (Σp)²/Σp² of its power over the
#: points within :data:`ehss.frequency.EXCITATION_FLOOR` of its peak, 2.0 for a sine on
#: a point and 2.16 halfway between two (the window's spectrum is zero two points from
#: its centre, its sidelobes 32 dB down). Random references fill 7.4–8.3 of the 10
#: points of 0.5–20 Hz in the H1 estimate of a 1.5-s window.
SINE_POINTS = 2.16
#: One-sided standard normal quantile of 1e-3: a fresh stretch whose residual is the
#: channel's usual one exceeds the bound :meth:`AdaptiveCompensator._judge_fit` sets
#: from it once in a thousand judgements.
QUIET_Z = 3.09


def _polarity_fault(model: ArmaxModel, band: tuple[float, float]) -> str:
    """A closed loop that tracks passes the low edge of its band in phase (|φ| < 90°)."""
    lo = max(band[0], 1e-3 * band[1])
    h = complex(model.frequency_response(np.array([lo]))[0])
    if h.real <= 0.0:
        return (f"the model's phase at the band's low edge ({lo:g} Hz) is "
                f"{math.degrees(math.atan2(h.imag, h.real)):.0f}°: a loop that follows its "
                "reference cannot be out of phase there (feedback sign or wiring?)")
    return ""


def _window_residual(model: ArmaxModel, u: np.ndarray, y: np.ndarray, n_fit: int,
                     n_usual: int) -> float:
    """RMS of ``y − ŷ`` (``ŷ``: ``model`` run free on ``u`` from the window's start) over
    the ``n_usual`` samples before the newest ``n_fit``; inf when there are none or the
    model cannot be run."""
    y_run = _free_run(model, u)
    if n_usual <= 0 or y_run is None:
        return math.inf
    with np.errstate(over="ignore", invalid="ignore"):
        e = (y - y_run)[-n_fit - n_usual:-n_fit]
        value = float(np.sqrt(np.mean(e * e)))
    return value if math.isfinite(value) else math.inf


def _excitation(h1: Any, band: tuple[float, float]) -> tuple[int, int, float]:
    """Points of ``band`` in the H1 estimate that its input excites
    (:meth:`ehss.FrequencyResponse.valid`), all its points there, and how many its
    input's power fills (the participation ratio, :data:`SINE_POINTS`); zeros for an
    estimate that does not say what its input excited."""
    power = getattr(h1, "input_power", None)
    if power is None:
        return 0, 0, 0.0
    lo, hi = band
    n_band = int(np.count_nonzero((h1.freq_hz >= lo) & (h1.freq_hz <= hi)))
    excited = h1.valid(band, 0.0)
    p = np.asarray(power, dtype=float)[excited]
    filled = float(p.sum() ** 2 / np.sum(p * p)) if p.size and np.any(p > 0) else 0.0
    return int(np.count_nonzero(excited)), n_band, filled


def _narrowband(h1: Any, band: tuple[float, float]) -> str:
    """Why ``h1`` cannot validate a model over ``band`` (empty if it can): its input's
    power fills fewer of the band's points than one and a half sines do (closer to one
    sine, :data:`SINE_POINTS`, than to two), where the band holds more than two sines'
    points (4 each) at the estimate's resolution: fewer are the resolution's doing, not
    the reference's, and are judged as before.

    A sine dwell after a random reference left the compensator that ran, which tracked
    100× better than none, but each model disagreed by 12–17° with the H1 estimate's
    points beside the sine (which hold its leakage, the loop's response at the sine's
    frequency rather than their own), and both channels of the simulated rig alarmed
    2 s in."""
    excited, n_band, filled = _excitation(h1, band)
    if n_band <= 8 or filled >= 1.5 * SINE_POINTS:
        return ""
    return (f"the reference fills {filled:.1f} of the band's {n_band} points of the H1 "
            "estimate, as a single sine does (a sine dwell, or a sweep slower than the "
            "window): nothing to validate a model over the band on")


class KeptRunning(ParameterError):
    """A design that, by its own model's account, would track worse than the
    compensator that runs: refused, and not a fault of the loop."""


@dataclass(frozen=True)
class Decision:
    """What :meth:`AdaptiveCompensator.propose` decided.

    Attributes
    ----------
    t_s : float
    accepted : bool
    reason : str
        Why not ("" when accepted).
    design : CompensatorDesign or None
        The new compensator (when accepted).
    figures : dict
        The figures judged (H1 agreement, drive gains), JSON-ready.
    fault : bool
        Whether a refusal says the model, the data or the drive may be wrong (True,
        the default: refusals in a row raise the compensator's alarm); False where the
        candidate passed those guards and only what runs is better, or missed the
        H1 agreement narrowly (:data:`NEAR_MISS`), which says nothing against the loop.
    """

    t_s: float
    accepted: bool
    reason: str
    design: CompensatorDesign | None = field(default=None, repr=False)
    figures: dict = field(default_factory=dict)
    fault: bool = True

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"t_s": self.t_s, "accepted": self.accepted,
                               "reason": self.reason, **self.figures}
        if self.design is not None:
            out.update(self.design.errors())
        return out


class AdaptiveCompensator:
    """The compensator of one channel, updated from its online model when it is safe.

    Parameters
    ----------
    fs_hz : float
    band_hz : (lo, hi)
        Band of the reference, which the model is validated over.
    mode : {"preview", "causal"}
    preview : int, optional
        See :func:`design_compensator`.
    n_taps, max_sections : int
        The target's sizes.
    guard : UpdateGuard, optional
    loop : str, optional
        With ``params``: the loop the drive is played into, whose limits it must respect
        (:func:`ehss.compensation.check_drive`).
    params : RigParams, optional

    Attributes
    ----------
    current : CompensatorDesign or None
        The last good design (None: no compensation yet).
    current_model : ArmaxModel or None
        The model it was designed from.
    log : list of Decision
    """

    def __init__(self, fs_hz: float, band_hz: tuple[float, float], *, mode: str = "preview",
                 preview: int | None = None, n_taps: int = 256, max_sections: int = 16,
                 guard: UpdateGuard | None = None, loop: str | None = None,
                 params: Any = None) -> None:
        if mode not in MODES:
            raise ParameterError(f"mode={mode!r} must be one of {MODES}")
        self.fs_hz = float(fs_hz)
        self.band_hz = (float(band_hz[0]), float(band_hz[1]))
        self.mode = mode
        self.preview = _check_preview(mode, preview, int(n_taps))
        self.n_taps = int(n_taps)
        self.max_sections = int(max_sections)
        self.guard = guard if guard is not None else UpdateGuard()
        self.loop, self.params = loop, params
        self.current: CompensatorDesign | None = None
        self.current_model: ArmaxModel | None = None
        self.log: list[Decision] = []
        self._last_t = -math.inf

    def due(self, t_s: float) -> bool:
        """Whether the rate limit lets an update through at ``t_s``."""
        return t_s - self._last_t >= self.guard.min_interval_s

    def propose(self, t_s: float, model: ArmaxModel, h1: Any, reference: np.ndarray,
                window: tuple[np.ndarray, np.ndarray] | None = None) -> Decision:
        """Judge the compensator of ``model`` at stream time ``t_s``.

        Parameters
        ----------
        t_s : float
        model : ArmaxModel
            The current online model.
        h1 : FrequencyResponse or None
            Sliding H1 estimate of the same loop (drive → feedback).
        reference : ndarray
            Recent reference (the desired output), to check the drive it would give.
        window : (u, y), optional
            The drive and feedback the H1 estimate was made from: the model simulated
            on ``u`` must fit the latest ``guard.fit_s`` of ``y`` (fresh data) as
            ``acceptance.min_fit_pct`` asks.

        Returns
        -------
        Decision
            Also appended to :attr:`log`; when accepted, :attr:`current` is its design.
        """
        decision = self.assess(t_s, model, h1, reference, window)
        self.record(decision, model)
        return decision

    def assess(self, t_s: float, model: ArmaxModel, h1: Any, reference: np.ndarray,
               window: tuple[np.ndarray, np.ndarray] | None = None, *,
               running: CompensatorDesign | None = None,
               residual_floor: float | None = None,
               usual_disagreement: tuple[float, float] | None = None) -> Decision:
        """The decision of :meth:`propose`, without recording it: changes nothing, so
        it may run on another thread or process than the one that records it.
        ``running``: the compensator the target runs (default :attr:`current`), which
        a design realised beyond the bounds must beat (:meth:`_realisable`);
        ``residual_floor``: the channel's usual residual on fresh data
        (:meth:`_judge_fit`); ``usual_disagreement``: how far (dB, degrees beyond the
        estimate's uncertainty) the channel's models usually miss the H1 estimate
        when they are no fault (:data:`NEAR_MISS`: a refusal within twice the larger
        of that and the bounds is a near miss)."""
        running = self.current if running is None else running
        decision = self._judge(t_s, model, h1, np.asarray(reference, dtype=float), running,
                               usual_disagreement)
        if decision.accepted and window is not None:
            decision = self._judge_fit(decision, model, *window, residual_floor=residual_floor)
        excited, n_band, _ = _excitation(h1, self.band_hz)
        if not decision.accepted and decision.fault and 2 * excited < n_band:
            # a reference that excites less than half the band (a sweep passing through,
            # a band wider than the reference's): a model fitted to it is right where it
            # was excited and extrapolated elsewhere, and its refusal says nothing
            # against the loop or the sensor (a random reference and then a sweep: the
            # sweep's faster part alarmed on both channels of the simulated rig while
            # the compensator that ran tracked it 60x better than none)
            decision = dataclasses.replace(decision, fault=False, figures={
                **decision.figures, "excited_points": [excited, n_band]})
        return decision

    def record(self, decision: Decision, model: ArmaxModel | None) -> None:
        """Take ``decision`` (on ``model``) into :attr:`log`, and its design as
        :attr:`current` when accepted."""
        self.log.append(decision)
        if decision.accepted:
            self.current = decision.design
            self.current_model = model
            self._last_t = decision.t_s

    def assess_correction(self, t_s: float, correction: Correction,
                          running: CompensatorDesign | None, reference: np.ndarray
                          ) -> Decision:
        """Whether the running compensator ``running`` (the :attr:`current` of when the
        data were taken), corrected by ``correction``, may replace it.

        The correction must leave at most :data:`CORRECTION_MAX_RATIO` of the tracking
        error on the newest samples, which it was not fitted to; its gain within
        :data:`CORRECTION_GAIN` and its phase within :data:`CORRECTION_PHASE_DEG` over
        the band; and the corrected compensator's drive must pass the gain checks and
        the rig's limits as any update's. Changes nothing (see :meth:`assess`).
        """
        figures = correction.figures()
        lo, hi = CORRECTION_GAIN
        if running is None:
            return Decision(t_s, False, "no compensator runs yet to correct", figures=figures)
        if not (lo <= correction.gain_range[0] and correction.gain_range[1] <= hi) \
                or correction.max_phase_deg > CORRECTION_PHASE_DEG:
            return Decision(t_s, False, f"the correction's gain over the band is "
                            f"{correction.gain_range[0]:.2f}-{correction.gain_range[1]:.2f}"
                            f" and its phase up to {correction.max_phase_deg:.0f}° (bounds "
                            f"{lo:.2f}-{hi:g}, {CORRECTION_PHASE_DEG:g}°): not a change of "
                            "a loop that tracks (feedback sign, sensor?)", figures=figures)
        if correction.check_ratio > CORRECTION_MAX_RATIO:
            return Decision(t_s, False, f"the correction leaves {correction.check_ratio:.2f}"
                            f" of the tracking error on fresh data (needs <= "
                            f"{CORRECTION_MAX_RATIO:g})", figures=figures)
        return self._checked_drive(t_s, lambda: fold_correction(running, correction),
                                   np.asarray(reference, dtype=float), figures)

    def _judge_fit(self, decision: Decision, model: ArmaxModel, u: np.ndarray,
                   y: np.ndarray, residual_floor: float | None = None) -> Decision:
        """The model's free-run simulation over the window must fit its latest part.

        The H1 estimate weighs the whole window; a sensor that fails (sticks, flips,
        bursts) shows first in the newest samples, which the model's simulation on the
        drive no longer fits. A fit below ``acceptance.min_fit_pct`` is a fault, unless
        the residual ``y − ŷ`` of those samples is no larger than the channel's usual
        one can be by chance: then the feedback is quiet or noisy, not wrong.

        The usual residual is ``residual_floor`` (the median over the channel's recent
        loads that fitted by ``min_fit_pct``, from
        :class:`ehss.live.compensate.ChannelAdapter`) or, before there is one, the
        model's own residual over the window's second half before those samples.

        * A reference that dies away (the end of an earthquake record) leaves the
          sensor's noise to be fitted, and the fit falls below 90 % while the loop and
          the sensor are as they were: on the simulated rig, an earthquake-like record
          of 40 s alarmed on both channels in its last 5 s.
        * A sensor whose noise is 10 % of the feedback allows no model a fit of 90 %:
          the 25 Hz servo was compensated only when a fit happened to reach it.
        * A stuck, flipped or drowned sensor leaves a residual as large as the
          feedback, many times the usual one.

        The bound is the usual residual times ``1 + z s``, with ``s`` the relative
        scatter of the ratio of the two RMS values (``1/√(2ν)`` for ν independent
        samples, ν = 2 B T in a band of B Hz over a stretch of T s; a floor from loads
        counts as exact) and z = :data:`QUIET_Z`: 1.70 over 0.5–20 Hz and 0.25 s
        against loads, 1.86 against the window's 0.5 s before.
        """
        acc = self.guard.acceptance
        n_fit = max(1, min(int(round(self.guard.fit_s * self.fs_hz)), u.size // 2))
        fit = free_run_fit(model, u, y, n_fit)
        spread = float(np.std(y[-n_fit:]))
        residual = (1.0 - fit / 100.0) * spread if math.isfinite(fit) else math.inf
        figures = {**decision.figures, "fresh_fit_pct": fit, "fresh_residual_rms": residual}
        if fit >= acc.min_fit_pct:
            return Decision(decision.t_s, True, "", decision.design, figures)
        usual, n_usual = residual_floor, None
        if usual is None:
            n_usual = u.size // 2 - n_fit
            usual = _window_residual(model, u, y, n_fit, n_usual)
        if not residual <= self._residual_bound(n_fit, n_usual) * usual:
            return Decision(decision.t_s, False, f"the model fits the latest "
                            f"{n_fit / self.fs_hz:g} s of feedback by {fit:.1f} % "
                            f"(needs {acc.min_fit_pct:g} %): the sensor or the loop "
                            "misbehaves", figures=figures)
        figures["quiet"] = (f"fits the latest {n_fit / self.fs_hz:g} s by {fit:.1f} % "
                            f"with a residual of {residual:.3g}, within the usual "
                            f"{usual:.3g} ({'its loads' if n_usual is None else 'the window'}"
                            "): a quiet or noisy feedback")
        return Decision(decision.t_s, True, "", decision.design, figures)

    def _residual_bound(self, n_fit: int, n_usual: int | None = None) -> float:
        """The residual bound's factor over the usual residual (:meth:`_judge_fit`),
        that of ``n_usual`` samples (None: of loads, exact)."""
        lo, hi = self.band_hz

        def nu(n: int) -> float:
            return max(1.0, 2.0 * (hi - lo) * n / self.fs_hz)

        var = 1.0 / (2.0 * nu(n_fit))
        if n_usual is not None:
            var += 1.0 / (2.0 * nu(max(1, n_usual)))
        return 1.0 + QUIET_Z * math.sqrt(var)

    def _judge(self, t_s: float, model: ArmaxModel, h1: Any, r: np.ndarray,
               running: CompensatorDesign | None = None,
               usual: tuple[float, float] | None = None) -> Decision:
        g = self.guard
        if not model.is_stable():
            radius = float(np.max(np.abs(np.roots(model.a))))
            return Decision(t_s, False, f"the model is unstable (pole radius {radius:.4g})")
        fault = _polarity_fault(model, self.band_hz)
        if fault:
            return Decision(t_s, False, fault)
        if h1 is None:
            return Decision(t_s, False, "no H1 estimate to confirm the model yet")
        acc = g.acceptance
        narrow = _narrowband(h1, self.band_hz)
        if narrow:
            return Decision(t_s, False, narrow, fault=False)
        # ArmaxModel's coefficients are read-only, which frf_error's protocol of a model
        # does not say (it reads them only)
        err = frf_error(cast(Any, model), h1, band_hz=self.band_hz, min_coherence=acc.min_coherence)
        figures: dict[str, float] = {"h1_points": err.n_points}
        if err.n_points < acc.min_frf_points:
            return Decision(t_s, False, f"the H1 estimate confirms {err.n_points} points of "
                            f"the band (coherence >= {acc.min_coherence:g}), fewer than "
                            f"{acc.min_frf_points}", figures=figures)
        mag_db, ph_deg = err.beyond_uncertainty(acc.uncertainty_sigmas)
        figures.update(h1_magnitude_db=mag_db, h1_phase_deg=ph_deg)
        if mag_db > acc.max_magnitude_db or ph_deg > acc.max_phase_deg:
            # a near miss is within NEAR_MISS of the bounds, or of the disagreements the
            # channel's own models usually show, if larger (``usual``)
            usual_db, usual_deg = (0.0, 0.0) if usual is None else usual
            gross = (mag_db > NEAR_MISS * max(acc.max_magnitude_db, usual_db)
                     or ph_deg > NEAR_MISS * max(acc.max_phase_deg, usual_deg))
            return Decision(t_s, False, f"{H1_DISAGREES} by "
                            f"{mag_db:.2f} dB / {ph_deg:.1f}° beyond its uncertainty (bounds "
                            f"{acc.max_magnitude_db:g} dB / {acc.max_phase_deg:g}°)",
                            figures=figures, fault=gross)
        return self._checked_drive(
            t_s, lambda: self._designed(model, figures, running), r, figures)

    def _designed(self, model: ArmaxModel, figures: dict[str, Any],
                  running: CompensatorDesign | None) -> CompensatorDesign:
        """The model's compensator with the inverse's slow modes left to the FIR, or, if
        the filter then realises it too poorly to be loaded (:meth:`_realisable`:
        refused, or kept out by the running one), with those that reach into the band
        run as sections, where that realises it better (:func:`design_compensator`).

        Only then: a model's slow mode is fitted to a window of 1.5 s and confirmed by
        no H1 point below the estimate's first bins (a few hertz), so a section that
        realises it faithfully realises what the data did not check. Where the FIR's
        approximation is loadable, it stays: on the 4 kHz specimen under a rolled-off
        reference, a slow section taken in whenever it realised the model's inverse
        better (0.09 dB / 0.9° against 0.74 dB / 14°) sent the channel's later models
        10 s of H1 disagreement, and left it 11× better than uncompensated against 25×.
        A loop behind a 0.5 Hz high-pass, whose FIR designs are refused as realised
        13–30 dB off, tracks 12.5–24× better than uncompensated with the sections,
        6.8–8.6× without them (README, "Where the defaults stop")."""
        def design(within: tuple[float, float]) -> CompensatorDesign:
            return design_compensator(model, band_hz=self.band_hz, mode=self.mode,
                                      preview=self.preview, n_taps=self.n_taps,
                                      max_sections=self.max_sections, within=within)

        try:
            return self._realisable(design((math.inf, math.inf)), model, figures, running)
        except (KeptRunning, ParameterError):
            acc = self.guard.acceptance
            return self._realisable(design((acc.max_magnitude_db, acc.max_phase_deg)),
                                    model, figures, running)

    def _realisable(self, design: CompensatorDesign, model: ArmaxModel,
                    figures: dict[str, Any], running: CompensatorDesign | None = None
                    ) -> CompensatorDesign:
        """``design``, unless in preview mode the target's filter realises the model's
        inverse so poorly that the loop would track worse with it than without, or
        than with the compensator that runs.

        The FIR's span and preview are samples, the loop's dynamics seconds: at a high
        rate a preview that suits a slower loop holds too little of the inverse (its
        delay's advance, the anti-causal tail of zeros outside the unit circle), and the
        filter then runs something else than the inverse. If the model is right, the
        compensated loop's relative tracking error over the band is the realisation's
        own, ``|C/T − 1|``, against ``|G − 1|`` without compensation: a design whose
        RMS over the band is not below that is refused. One realised beyond the bounds
        a model must meet against the H1 estimate (``acceptance.max_magnitude_db`` /
        ``max_phase_deg``) but still better than none is loaded, and ``figures`` says
        so (``"realisation"``: how far ahead the target reads, and to give it more),
        unless by the same model's account the compensator that runs (``running``)
        leaves less, ``|G C_run − 1|``: a model whose inverse the filter cannot follow
        (a sharp feature at the band's edge) does not replace one that it follows.
        The causal mode's FIR is a prediction, whose error is the price of having no
        preview: not checked here.

        Raises
        ------
        ParameterError
            The realisation would leave more error than no compensation.
        KeptRunning
            It would leave more than the compensator that runs.
        """
        acc = self.guard.acceptance
        mag, ph = design.max_amplitude_error_db, design.max_phase_error_deg
        if design.mode != "preview" or (mag <= acc.max_magnitude_db
                                        and ph <= acc.max_phase_deg):
            return design
        ahead = (f"its {design.taps.size} taps read {design.preview} samples ahead "
                 f"({1e3 * design.preview / design.fs_hz:.3g} ms at {design.fs_hz:g} Hz)")
        left = float(np.sqrt(np.mean(np.abs(design.error) ** 2)))
        g = model.frequency_response(design.freq_hz)
        without = float(np.sqrt(np.mean(np.abs(g - 1.0) ** 2)))
        if left >= without:
            raise ParameterError(
                f"the target's filter realises the model's inverse only to {mag:.2f} dB / "
                f"{ph:.1f}° over the band, which would leave {left:.0%} of the reference "
                f"against {without:.0%} without compensation: {ahead}, too few for this "
                "loop's inverse; give the target more preview or narrow the band")
        if running is not None and running.mode == design.mode:
            kept = float(np.sqrt(np.mean(np.abs(
                g * running.frequency_response(design.freq_hz) - 1.0) ** 2)))
            if left >= kept:
                raise KeptRunning(
                    f"the target's filter realises the model's inverse only to {mag:.2f} "
                    f"dB / {ph:.1f}° over the band, which would leave {left:.1%} of the "
                    f"reference against {kept:.1%} with the compensator that runs")
        figures["realisation"] = (
            f"realised to {mag:.2f} dB / {ph:.1f}° over the band (bounds "
            f"{acc.max_magnitude_db:g} dB / {acc.max_phase_deg:g}°): {ahead}; more "
            "preview would track better")
        return design

    def _checked_drive(self, t_s: float, design_of: Callable[[], CompensatorDesign],
                       r: np.ndarray, figures: dict[str, Any]) -> Decision:
        """The design, if its drive for the recent reference passes the gain checks and
        the rig's limits.

        A drive that would pass once divided by :data:`NEAR_MISS` (its gains and its
        peaks against the rig's limits at most twice their bounds) is refused but is no
        fault: the inverse of a right model asks that much where the band reaches past
        the loop's bandwidth, or where the reference itself runs near the rig's limits,
        and a peak scatters with the reference's content. The 25 Hz servo under a
        1–60 Hz reference asks peaks of 3.12–3.14× against 3× now and then, amid loads,
        and alarmed twice in 30 s; the rig's position loop under its default reference
        asked a peak velocity of 0.2041 m/s against its 0.2 m/s and alarmed once in
        2 minutes. A model gone wrong asks many times more."""
        g = self.guard
        drive, skip = None, 0
        try:
            design = design_of()
            drive = run_compensator(design, r)
            skip = min(design.settle_samples, r.size // 2)
            check = check_drive(drive[skip:], r[skip:], self.fs_hz, max_gain=g.max_gain,
                                limits=g.limits, loop=self.loop, params=self.params)
        except KeptRunning as exc:
            return Decision(t_s, False, str(exc), figures=figures, fault=False)
        except EhssError as exc:
            near = drive is not None and self._passes(drive[skip:] / NEAR_MISS, r[skip:])
            return Decision(t_s, False, str(exc), figures=figures, fault=not near)
        figures.update(rms_gain=check.rms_gain, peak_gain=check.peak_gain)
        return Decision(t_s, True, "", design, figures)

    def _passes(self, drive: np.ndarray, r: np.ndarray) -> bool:
        """Whether ``drive`` for ``r`` passes the checks of :meth:`_checked_drive`."""
        g = self.guard
        try:
            check_drive(drive, r, self.fs_hz, max_gain=g.max_gain, limits=g.limits,
                        loop=self.loop, params=self.params)
        except EhssError:
            return False
        return True
