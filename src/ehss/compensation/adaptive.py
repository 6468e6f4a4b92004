"""Adaptive inverse-model compensation: the inverse of the online model, updated safely.

A rig identified online (:class:`ehss.RelsEstimator`) has, at any time, a model
``G = q^-d B/A`` of its closed loop, which
:func:`~ehss.compensation.compensator_design.design_compensator` turns into the
compensator a real-time target runs, and which, after a change of the rig,
:mod:`~ehss.compensation.correction` corrects before a new model can be trusted.

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
:class:`~ehss.workflow.Acceptance` asks of a validated model, :func:`free_run_fit`).
Otherwise the last good compensator stays and the reason is logged. Updates are at most
one per ``min_interval_s``. A correction of the running compensator
(:func:`~ehss.compensation.correction.fit_correction`) is guarded by
:meth:`AdaptiveCompensator.assess_correction`.

References: eqs (16)–(22) of the paper (the model and its recursive estimate).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np
import scipy.signal

from ehss._checks import check_real
from ehss.compensation.checks import (
    DEFAULT_MAX_GAIN,
    DEFAULT_MIN_GAIN,
    DriveLimits,
    check_drive,
)
from ehss.compensation.compensator_design import (
    FEWEST_TAPS,
    MODES,
    CompensatorDesign,
    _check_preview,
    design_compensator,
    fir_modes_hz,
    fir_taps,
    run_compensator,
)
from ehss.compensation.correction import (
    CORRECTION_GAIN,
    CORRECTION_MAX_RATIO,
    CORRECTION_PHASE_DEG,
    Correction,
    fold_correction,
)
from ehss.errors import EhssError, ParameterError
from ehss.identification.model import ArmaxModel
from ehss.validation import FrfError, frf_error
from ehss.workflow import Acceptance

__all__ = [
    "H1_DISAGREES",
    "UpdateGuard",
    "Decision",
    "AdaptiveCompensator",
    "free_run_fit",
    "KeptRunning",
]

#: How a refusal for the model's disagreement with the H1 estimate begins.
H1_DISAGREES = "the model disagrees with the H1 estimate"


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
#: The share of the H1 estimate's points at the band's low (or top) edge that a model
#: may miss and still be validated over the rest
#: (:meth:`AdaptiveCompensator._validated_from`).
EDGE_SHARE = 0.25
#: Frequencies over the band at which a narrowed inverse and the running compensator
#: are compared by the model's account (:meth:`AdaptiveCompensator._tops`).
NARROWING_GRID = 128
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
class Narrowing:
    """The bands a drive beyond the gain checks may be narrowed to: their tops (Hz,
    lowest first), the design over the band up to a top (what its realisation says,
    :meth:`AdaptiveCompensator._realisable`, in ``notes``, of the latest design), the
    relative tracking error (RMS over the whole band) a design leaves by the model's
    account, and what the compensator that runs leaves by it (inf: none runs)."""

    tops: np.ndarray
    design: Callable[[float], CompensatorDesign]
    leaves: Callable[[CompensatorDesign], float]
    kept: float
    notes: dict = field(default_factory=dict)


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
        The target's sizes (``n_taps`` default :func:`~ehss.compensation.
        compensator_design.fir_taps` of ``fs_hz`` and ``preview``). Each design is
        as long as pays, between :data:`~ehss.compensation.compensator_design.
        FEWEST_TAPS` (or twice the preview) and ``n_taps`` (``fewest_taps`` of
        :func:`~ehss.compensation.compensator_design.design_compensator`).
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
                 preview: int | None = None, n_taps: int | None = None,
                 max_sections: int = 16,
                 guard: UpdateGuard | None = None, loop: str | None = None,
                 params: Any = None) -> None:
        if mode not in MODES:
            raise ParameterError(f"mode={mode!r} must be one of {MODES}")
        self.fs_hz = float(fs_hz)
        self.band_hz = (float(band_hz[0]), float(band_hz[1]))
        self.mode = mode
        if n_taps is None:
            n_taps = fir_taps(self.fs_hz, preview or 0)
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
               usual_disagreement: tuple[float, float] | None = None,
               low_edge: bool = False, top_edge: bool = False,
               narrow_top: bool = False) -> Decision:
        """The decision of :meth:`propose`, without recording it: changes nothing, so
        it may run on another thread or process than the one that records it.
        ``running``: the compensator the target runs (default :attr:`current`), which
        a design realised beyond the bounds must beat (:meth:`_realisable`);
        ``residual_floor``: the channel's usual residual on fresh data
        (:meth:`_judge_fit`); ``usual_disagreement``: how far (dB, degrees beyond the
        estimate's uncertainty) the channel's models usually miss the H1 estimate
        when they are no fault (:data:`NEAR_MISS`: a refusal within twice the larger
        of that and the bounds is a near miss); ``low_edge``: the channel's models
        have missed the estimate at the band's lowest point again and again, so that a
        model that misses it only there is validated over the band above
        (:meth:`_validated_from`); ``top_edge``: the same at the band's top point;
        ``narrow_top``: the channel's validated models have asked drives beyond the
        gain checks or the rig's limits again and again, so that a model whose drive
        over the band would fail them is compensated up to where it passes
        (:meth:`_narrowed`)."""
        running = self.current if running is None else running
        decision = self._judge(t_s, model, h1, np.asarray(reference, dtype=float), running,
                               usual_disagreement, low_edge, top_edge, narrow_top)
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
               usual: tuple[float, float] | None = None, low_edge: bool = False,
               top_edge: bool = False, narrow_top: bool = False) -> Decision:
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
        lo = self._validated_from(err) if low_edge else None
        hi = self._validated_from(err, top=True) if top_edge and lo is None else None
        if lo is not None or hi is not None:
            # validated from lo up (or up to hi): the inverse over that band only
            band = (self.band_hz[0] if lo is None else lo,
                    self.band_hz[1] if hi is None else hi)
            kept_db, kept_deg = err.beyond_uncertainty(
                acc.uncertainty_sigmas, (err.freq_hz >= band[0]) & (err.freq_hz <= band[1]))
            figures.update({"validated_from_hz" if hi is None else "validated_to_hz":
                            band[0] if hi is None else band[1]})
            figures.update(h1_edge_magnitude_db=mag_db, h1_edge_phase_deg=ph_deg,
                           h1_magnitude_db=kept_db, h1_phase_deg=kept_deg)
            return self._checked_drive(
                t_s, lambda: self._designed(model, figures, running, band), r, figures,
                self._tops(err, band, model, running) if narrow_top else None)
        if mag_db > acc.max_magnitude_db or ph_deg > acc.max_phase_deg:
            # a near miss is within NEAR_MISS of the bounds, or of the disagreements the
            # channel's own models usually show, if larger (``usual``)
            gross = self.gross(mag_db, ph_deg, usual)
            worst = err.worst_beyond_uncertainty(acc.uncertainty_sigmas,
                                                 acc.max_magnitude_db, acc.max_phase_deg)
            figures.update(h1_worst_hz=worst, h1_lowest_hz=err.compared_hz[0],
                           h1_highest_hz=err.compared_hz[1])
            return Decision(t_s, False, f"{H1_DISAGREES} by "
                            f"{mag_db:.2f} dB / {ph_deg:.1f}° beyond its uncertainty, "
                            f"furthest at {worst:.3g} Hz (bounds "
                            f"{acc.max_magnitude_db:g} dB / {acc.max_phase_deg:g}°)",
                            figures=figures, fault=gross)
        return self._checked_drive(
            t_s, lambda: self._designed(model, figures, running), r, figures,
            self._tops(err, self.band_hz, model, running) if narrow_top else None)

    def gross(self, mag_db: float, ph_deg: float,
              usual: tuple[float, float] | None = None) -> bool:
        """Whether a model that misses the H1 estimate by ``mag_db`` / ``ph_deg``
        beyond its uncertainty misses it by more than :data:`NEAR_MISS` times the
        larger of the bounds and the channel's ``usual`` disagreement (a fault), not
        within them (a near miss)."""
        acc = self.guard.acceptance
        usual_db, usual_deg = (0.0, 0.0) if usual is None else usual
        return (mag_db > NEAR_MISS * max(acc.max_magnitude_db, usual_db)
                or ph_deg > NEAR_MISS * max(acc.max_phase_deg, usual_deg))

    def _tops(self, err: FrfError, band: tuple[float, float], model: ArmaxModel,
              running: CompensatorDesign | None) -> Narrowing:
        """The bands a drive beyond the checks may be narrowed to (:meth:`_narrowed`):
        ``band`` with its top at each point of the H1 estimate compared inside it that
        has ``min_frf_points`` compared points at or below it, lowest first, and the
        model's design over each."""
        lo, hi = band
        f = np.sort(err.freq_hz[(err.freq_hz > lo) & (err.freq_hz < hi)])
        tops = f[self.guard.acceptance.min_frf_points - 1:]
        grid = np.linspace(lo, hi, NARROWING_GRID)
        g = model.frequency_response(grid)

        def leaves(design: CompensatorDesign) -> float:
            return float(np.sqrt(np.mean(np.abs(g * design.frequency_response(grid) - 1.0)
                                         ** 2)))

        notes: dict[str, Any] = {}

        def design(top: float) -> CompensatorDesign:
            # against no running compensator: each band is tried for its drive, and the
            # one found is compared with what runs over the whole band (``kept``).
            # Compared over each narrower band, a narrowed compensator that runs left
            # less below its own top than any design there, the search took those
            # bands for failing and ended with none (tests/compensation/
            # test_adaptive.py, a narrowed compensator running)
            notes.clear()
            return self._designed(model, notes, None, (lo, top))

        kept = leaves(running) if running is not None and running.mode == self.mode \
            else math.inf
        return Narrowing(tops, design, leaves, kept, notes)

    def _validated_from(self, err: FrfError, *, top: bool = False) -> float | None:
        """The lower edge of the band over which a model is validated when it misses
        the H1 estimate (beyond its uncertainty and the bounds) only at the band's
        lowest points, at most :data:`EDGE_SHARE` of them, and agrees with it at
        ``min_frf_points`` or more above: halfway between the last point it misses and
        the first it meets. None when it misses nowhere or elsewhere too. With ``top``,
        the upper edge of a model that misses only at the band's highest points.

        The band's lowest points are where a model fitted to a window of 1.5 s says
        least: a slow mode or a high-pass below the band (drift control, an
        accelerometer's or a reference generator's high-pass) leads the loop's phase
        there, and neither the window nor the recursive estimate's weighting of the
        band resolves it. On the simulated rig's acceleration loop at 5 kHz under a
        3–50 Hz reference, 53 of 61 refused models missed the estimate furthest at its
        lowest point, 4.88 Hz, by 10–17° (the loop's own phase there is −10°, and the
        estimate is within 0.5° of it), and agreed with it above: refused whole, they
        left the channel 9.6× better than uncompensated; compensated from 6 Hz up
        (``--band 6 50``), 16×. Such a model's inverse over the band it is validated
        over is the exact one there, and below it the compensator passes the
        reference as the loop would run without it.

        The band's highest points are the other end of the same: a band that reaches
        past what the loop follows (a specimen's resonance, a bandwidth that a heavier
        payload lowered) ends where the loop's response is small, the feedback there
        mostly noise, and a sixth-order model of a loop of higher order misses it
        there first. The actuator on its specimen at 4 kHz under a 1–100 Hz reference,
        compensated up to where its drive passes (near 72 Hz, :meth:`_narrowed`), had
        its later models refused furthest at 99.6 Hz, the band's top, by up to 7 dB /
        38°, which alarmed on a loop that was fine."""
        acc = self.guard.acceptance
        if err.n_points == 0:
            return None
        order = np.argsort(err.freq_hz)[::-1] if top else np.argsort(err.freq_hz)
        f = err.freq_hz[order]
        mag, ph = err.excess(acc.uncertainty_sigmas)
        beyond = ((mag > acc.max_magnitude_db) | (ph > acc.max_phase_deg))[order]
        if not beyond[0] or beyond.all():
            return None
        k = int(np.argmin(beyond))      # the first point the model meets
        if beyond[k:].any() or k > EDGE_SHARE * f.size \
                or f.size - k < acc.min_frf_points:
            return None
        return float(0.5 * (f[k - 1] + f[k]))

    def _designed(self, model: ArmaxModel, figures: dict[str, Any],
                  running: CompensatorDesign | None,
                  band: tuple[float, float] | None = None) -> CompensatorDesign:
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
        6.8–8.6× without them (docs/adaptive_compensation.md, "Where the defaults stop").

        A mode the FIR is left that lies in the band is no slow mode but a lightly
        damped resonance of the inverse (:func:`fir_modes_hz`), where the H1 estimate
        does check the model: a design that then misses the bounds is replaced by the
        one with sections if that realises the inverse better. On a 12 Hz loop with a
        50 Hz, ζ 0.08 table mode at 1 kHz under a 0.5–40 Hz reference, +40 % mass
        moved the mode to 42 Hz; its models were right (within 0.1 dB / 1° of the loop
        to 42 Hz), but their inverses' resonance, radius 0.9694 against the FIR's
        0.9692, was left to the FIR, realised 3–10 dB off (28–38 % at the band's
        bottom) and loaded as better than the running one: channel 1 stayed at 14× its
        level before for 6 s, against 0.75× with the heavier mass from the start. The
        sections realise it to 0.02 dB and settle in 482 samples instead of 265
        (docs/adaptive_compensation.md, "A table mode that a change moves to the band's
        top")."""
        def design(within: tuple[float, float]) -> CompensatorDesign:
            return design_compensator(model, band_hz=band or self.band_hz, mode=self.mode,
                                      preview=self.preview, n_taps=self.n_taps,
                                      max_sections=self.max_sections, within=within,
                                      fewest_taps=max(FEWEST_TAPS, 2 * self.preview))

        acc = self.guard.acceptance
        bounds = (acc.max_magnitude_db, acc.max_phase_deg)
        try:
            first = self._realisable(design((math.inf, math.inf)), model, figures, running)
        except (KeptRunning, ParameterError):
            return self._realisable(design(bounds), model, figures, running)
        lo = (band or self.band_hz)[0]
        if (first.max_amplitude_error_db > bounds[0] or first.max_phase_error_deg > bounds[1]) \
                and np.any(fir_modes_hz(first) >= lo):
            try:
                sections = design(bounds)
            except ParameterError:      # more sections than the target runs
                return first
            # it realises the inverse better, so it passes where the first passed
            if np.mean(np.abs(sections.error) ** 2) < np.mean(np.abs(first.error) ** 2):
                figures.pop("realisation", None)
                return self._realisable(sections, model, figures, running)
        return first

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

        A design realised within the bounds is held to the same comparison: by the
        model's own account it must leave less than the compensator that runs. Both
        figures are the one model's, over the same grid, so the comparison weighs
        nothing the data do not: where the model says the running compensator tracks
        better, a load can only make the tracking worse or leave it as it is. Without
        it, models that fitted their windows by 99 % but whose inverses the filter
        realised less well (a lightly damped mode near the band's top) replaced one
        another, each within the bounds: on a 15 Hz loop with an oil-column mode moved
        to 34 Hz by +40 % mass, sampled at 2 kHz and compensated over 1–40 Hz, the
        realisation error of the loaded designs went from 0.9 % to 2.1, 3.9 and 5 % of
        the reference in 5 s, and the tracking error from 1.2× its level before the
        change to 5× (docs/adaptive_compensation.md, "On loops that are not the rig").

        Raises
        ------
        ParameterError
            The realisation would leave more error than no compensation.
        KeptRunning
            It would leave more than the compensator that runs.
        """
        acc = self.guard.acceptance
        mag, ph = design.max_amplitude_error_db, design.max_phase_error_deg
        if design.mode != "preview":
            return design
        left = float(np.sqrt(np.mean(np.abs(design.error) ** 2)))
        g = model.frequency_response(design.freq_hz)
        kept = math.inf
        if running is not None and running.mode == design.mode:
            kept = float(np.sqrt(np.mean(np.abs(
                g * running.frequency_response(design.freq_hz) - 1.0) ** 2)))
        if mag <= acc.max_magnitude_db and ph <= acc.max_phase_deg:
            if left >= kept:
                raise KeptRunning(
                    f"the target's filter realises the model's inverse to {left:.1%} of "
                    f"the reference over the band; by the same model the compensator "
                    f"that runs leaves {kept:.1%}")
            return design
        ahead = (f"its {design.taps.size} taps read {design.preview} samples ahead "
                 f"({1e3 * design.preview / design.fs_hz:.3g} ms at {design.fs_hz:g} Hz)")
        without = float(np.sqrt(np.mean(np.abs(g - 1.0) ** 2)))
        if left >= without:
            raise ParameterError(
                f"the target's filter realises the model's inverse only to {mag:.2f} dB / "
                f"{ph:.1f}° over the band, which would leave {left:.0%} of the reference "
                f"against {without:.0%} without compensation: {ahead}, too few for this "
                "loop's inverse; give the target more preview or narrow the band")
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
                       r: np.ndarray, figures: dict[str, Any],
                       narrowing: Narrowing | None = None) -> Decision:
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
        2 minutes. A model gone wrong asks many times more.

        With ``narrowing`` (:meth:`_tops`), a drive that fails is tried again from the
        designs over narrower bands (:meth:`_narrowed`), and the band found is
        accepted with its top (``narrowed_to_hz``) if by the model's account it tracks
        the whole band better than the compensator that runs; a refused drive is marked
        (``drive_refused``) so that the channel can count such refusals in a row."""
        drive, skip = None, 0
        try:
            design = design_of()
            drive = run_compensator(design, r)
            skip = min(design.settle_samples, r.size // 2)
            check = self._check(drive[skip:], r[skip:])
        except KeptRunning as exc:
            return Decision(t_s, False, str(exc), figures=figures, fault=False)
        except EhssError as exc:
            if drive is None:   # no design to drive with
                return Decision(t_s, False, str(exc), figures=figures)
            figures["drive_refused"] = True
            if narrowing is not None and (narrowed := self._narrowed(narrowing, r)):
                design, top, check, notes = narrowed
                left = narrowing.leaves(design)
                if left >= narrowing.kept:
                    return Decision(t_s, False, (
                        f"{exc}; up to {top:.3g} Hz, where its drive passes, its inverse "
                        f"would leave {left:.1%} of the reference over the band against "
                        f"{narrowing.kept:.1%} with the compensator that runs"),
                        figures=figures, fault=False)
                del figures["drive_refused"]
                figures.pop("realisation", None)    # the whole band's, if any
                figures.update(notes, narrowed_to_hz=top, rms_gain=check.rms_gain,
                               peak_gain=check.peak_gain, narrowed_leaves=left)
                return Decision(t_s, True, "", design, figures)
            near = self._passes(drive[skip:] / NEAR_MISS, r[skip:])
            return Decision(t_s, False, str(exc), figures=figures, fault=not near)
        figures.update(rms_gain=check.rms_gain, peak_gain=check.peak_gain)
        return Decision(t_s, True, "", design, figures)

    def _narrowed(self, narrowing: Narrowing, r: np.ndarray
                  ) -> tuple[CompensatorDesign, float, Any, dict] | None:
        """The design over a band of ``narrowing`` whose drive for ``r`` passes the
        gain checks and the rig's limits, with its top, its check and its realisation's
        notes; None if none that the search tries does.

        A model validated over the band whose inverse still asks too much there is
        right: the band reaches past what the loop can follow within the rig's bounds
        (a specimen's resonance, a bandwidth that a heavier payload lowered), and the
        inverse's gain grows with frequency beyond it. The exact inverse up to a
        frequency the drive allows tracks the band below it as the full inverse would
        (above it the design's own transition runs, as outside any band), where the
        last good inverse, built on a loop that has since changed, may track worse;
        which of the two leaves less over the whole band, by the model's account,
        decides (:meth:`_checked_drive`). The tops are searched by bisection, a
        design and a drive each: the drive's demand grows with the band broadly but
        not strictly (its peak moves with the reference's content), so the band found
        passes and the band one point wider does not, but a wider one may pass
        again."""
        found = None
        first, last = 0, narrowing.tops.size - 1
        while first <= last:
            mid = (first + last) // 2
            try:
                design = narrowing.design(float(narrowing.tops[mid]))
                skip = min(design.settle_samples, r.size // 2)
                check = self._check(run_compensator(design, r)[skip:], r[skip:])
            except EhssError:
                last = mid - 1
                continue
            found = (design, float(narrowing.tops[mid]), check, dict(narrowing.notes))
            first = mid + 1
        return found

    def _check(self, drive: np.ndarray, r: np.ndarray) -> Any:
        """The gain checks and the rig's limits of a new compensator's ``drive`` for
        ``r`` (:func:`~ehss.compensation.check_drive`; raises if it fails)."""
        g = self.guard
        return check_drive(drive, r, self.fs_hz, max_gain=g.max_gain, limits=g.limits,
                           loop=self.loop, params=self.params)

    def _passes(self, drive: np.ndarray, r: np.ndarray) -> bool:
        """Whether ``drive`` for ``r`` passes the checks of :meth:`_checked_drive`."""
        return not self._drive_error(drive, r)

    def _drive_error(self, drive: np.ndarray, r: np.ndarray, *, gains: bool = True) -> str:
        """Why ``drive`` for ``r`` fails the checks of :meth:`_checked_drive` (empty if
        it passes; without ``gains``, the rig's limits alone)."""
        g = self.guard
        max_gain, min_gain = (g.max_gain, DEFAULT_MIN_GAIN) if gains else (None, None)
        try:
            check_drive(drive, r, self.fs_hz, max_gain=max_gain, min_gain=min_gain,
                        limits=g.limits, loop=self.loop, params=self.params)
        except EhssError as exc:
            return str(exc)
        return ""

    def drive_fault(self, drive: Any, reference: Any, *, gains: bool = True) -> str:
        """Why the drive the target ran for ``reference`` fails the checks a new
        compensator's drive must pass (the gains against the reference, unless
        ``gains`` is False, and the rig's limits) as a fault, or empty: if it passes
        divided by :data:`NEAR_MISS` (a refusal of a new compensator that near is no
        fault either: the servo's inverse over 1–60 Hz asks 3.02–3.47× now and then),
        or if the reference itself is beyond the rig's limits (no compensator can keep
        the drive within them there, none included)."""
        drive = np.asarray(drive, dtype=float)
        reference = np.asarray(reference, dtype=float)
        if not self._drive_error(drive / NEAR_MISS, reference, gains=gains) \
                or self._drive_error(reference, reference, gains=False):
            return ""
        return self._drive_error(drive, reference, gains=gains)
