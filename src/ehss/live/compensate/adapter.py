"""Adaptive compensation while the rig runs: the online model's inverse, sent to the target.

Each channel has its own recursive estimator of the loop from the drive it receives to
its feedback (:class:`ehss.RelsEstimator`, eqs (19)–(22) of the paper), the sliding
windows of drive, feedback and desired reference, and an
:class:`~ehss.compensation.adaptive.AdaptiveCompensator`. Every ``update_s`` of stream
time the current model is judged (:class:`~ehss.compensation.adaptive.UpdateGuard`);
a compensator that passes is sent to the target (:meth:`Target.load`), which runs it in
shadow until its start-up has died out and cross-fades it in; one that fails is not
sent, the last good one keeps running, and the refusal is logged (an alarm when a
channel that had a good compensator starts refusing, a clear when it accepts again).
A judgement runs on a worker (:attr:`CompensationSettings.judge_in`) on a copy of the
channel's windows and θ̂ (:class:`Snapshot`, :class:`Judging`), and its decision is
taken up at the next channel's turn, so that the stream's samples never wait for a
design. A change of the loop shows first in the channel's own tracking error: a quick
sequential test on it (:class:`~ehss.live.detect.TrackingTrigger`) makes the
channel's first estimator follow for a while (:meth:`ChannelAdapter.follow_change`)
and, in preview mode, has the running compensator corrected from the data since the
change (:func:`~ehss.compensation.adaptive.fit_correction`, a five-tap FIR folded into
it) until the full model's inverse takes over again. A rise that the trigger dates to
the fade-in of a load, while the model of before still matches the loop, is that
compensator's: the one before it is sent again (``"kind": "compensator_rollback"``),
and the trigger tests on against the level it had learnt.

The target is anything with ``load(channel, compensator, apply_index, crossfade)``,
``step(n) -> RigBlock``, ``index``, ``finished``, ``fs``, ``channels``, ``preview`` and
either the whole ``desired`` reference or its ``reference_rms``:
:class:`ehss.live.rig.SteppingRig` in process, or :class:`UdpTarget`, a remote target
whose compensators :class:`DatagramSender` sends as :mod:`ehss.target.datagram`
datagrams. ``apply_index`` counts drive samples from the start of the stream.
"""

from __future__ import annotations

import collections
import dataclasses
import math
import re
import time
from collections.abc import Callable
from concurrent.futures import Executor, Future, ProcessPoolExecutor, ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

import ehss
from ehss._checks import check_int, check_real
from ehss._settle import SETTLE_TIME_CONSTANTS, decay_samples
from ehss.compensation.adaptive import (
    MODES,
    AdaptiveCompensator,
    CompensatorDesign,
    Decision,
    UpdateGuard,
    compare_compensators,
    fit_correction,
    free_run_fit,
)
from ehss.errors import EhssError, ParameterError
from ehss.frequency import FrequencyResponse
from ehss.identification import oe_pem
from ehss.live.channel import reference_band
from ehss.live.detect import (
    ONSET_Z,
    BaselineResidual,
    TrackingTrigger,
    TriggerSettings,
    block_statistic,
)

__all__ = ["CompensationSettings", "ChannelAdapter", "AdaptiveLoop", "CompensationRecord",
           "Target", "DatagramSender", "UdpTarget", "JUDGE_IN", "Snapshot", "Verdict",
           "Judging", "seen_alike"]


#: Independent samples of the band per parameter that a model's refit to its output
#: errors needs (:meth:`Judging.refine`), a record of T s in a band of B Hz holding
#: about 2 B T of them: two, half as many as a correction's taps ask
#: (:func:`~ehss.compensation.adaptive.fit_correction`), since a refit starts next to
#: its answer (the recursive estimate, the running model) and its prior record holds
#: the loop above the band, which the rows do not. Four made it come after the correction on the
#: simulated rig (0.81 s against 1.23 s of data), which left −30 % payload on one pair
#: of references at 2.6× over the first 2 s (README, "Adaptive compensation").
REFINE_SAMPLES = 2
#: A reference this far below its usual RMS (20 dB) is quiet (:meth:`Judging._quiet`).
QUIET_REFERENCE = 0.1
#: The H1 window's length where the band is wide enough (s), and how many of the
#: estimate's points a narrower band must hold in it
#: (:meth:`CompensationSettings.h1_window_for`): its segments are a third of the window,
#: and the narrowband test needs more than 8 (:mod:`ehss.compensation.adaptive`).
H1_WINDOW_S = 1.5
H1_BAND_POINTS = 8
#: Loads whose residual on fresh data make a channel's usual one (their median, the
#: floor of :meth:`ehss.compensation.AdaptiveCompensator._judge_fit`): at least the
#: first, at most the last.
RESIDUAL_LOADS = (3, 20)
#: How far a channel's models usually miss the H1 estimate: this quantile, over its last
#: judgements that were no fault (loads and near misses), of the magnitude and phase
#: disagreements beyond the estimate's uncertainty, once there are enough of them;
#: a refusal within :data:`ehss.compensation.adaptive.NEAR_MISS` times the larger of
#: that and the bounds is a near miss. On the simulated rig its models' 90th percentile
#: stays within the bounds (1 dB / 5°) and nothing changes; on a loop behind a 0.5 Hz
#: high-pass, whose models miss the band's low end by 5–10° half of the time, three
#: refusals of 12° in a row alarmed once in 10 stationary channel-minutes.
USUAL_DISAGREEMENT = 0.9
#: The fewest and the most judgements :data:`USUAL_DISAGREEMENT` is taken over.
USUAL_JUDGEMENTS = (10, 40)
#: Evaluations of each of a refit's Levenberg–Marquardt runs (from a nearby start it
#: converges in 4–8; 30 changed no figure of the README's rig tables)
REFINE_EVALUATIONS = 15
#: Channels × sample rate (samples a second) up to which :class:`AdaptiveLoop` refits
#: the models by default (``CompensationSettings.refine`` None). A refit's cost grows
#: with the rows of its window: 7 ms a judgement at 1 kHz, 20 ms at 5 kHz on the
#: machine of BENCHMARKS.md, every ``update_s`` per channel. Up to 16 000
#: channel-samples a second (3 channels at 5 kHz, 8 at 2 kHz) that leaves the worker
#: most of a core; 8 channels at 5 kHz would need more than one.
REFINE_LOAD = 16_000.0
#: Seed of the noise that carries the prior (:meth:`Judging._prior`)
PRIOR_SEED = 0
#: Length of that noise in start-ups of the prior (or in its parameters, if more)
PRIOR_LENGTH = 4

#: where :class:`AdaptiveLoop` judges (:attr:`CompensationSettings.judge_in`)
JUDGE_IN = ("process", "thread", "stream")


class Target(Protocol):
    """What :class:`AdaptiveLoop` drives."""

    fs: float
    channels: tuple[str, ...]
    preview: int
    index: int

    def load(self, channel: int, compensator: Any, apply_index: int, crossfade: int) -> bool:
        """Hand over a compensator (False if the target refuses it)."""

    def step(self, n: int) -> Any:
        """Run the next ``n`` samples; a block with ``first_index``, ``desired``,
        ``drive`` and ``feedback`` (each shape (n_channels, n))."""

    @property
    def finished(self) -> bool:
        """True when the test is over.

        A target that runs on its own clock (:class:`UdpTarget`) also has ``ahead()``:
        how many samples it is estimated to be past ``index`` now; a compensator is
        scheduled that much later, so that it still runs its settling time in shadow
        before its apply index. A target stepped in process needs none."""


def _ahead(target: Target) -> int:
    """Samples ``target`` is past its ``index`` now (0 if it does not say)."""
    ahead = getattr(target, "ahead", None)
    return int(ahead()) if callable(ahead) else 0


@dataclass(frozen=True, kw_only=True)
class CompensationSettings:
    """Settings of adaptive compensation.

    Attributes
    ----------
    mode : {"preview", "causal"}
    band_hz : (lo, hi), optional
        Band of the compensation and of the model's validation; default the band of the
        desired reference (within 20 dB of its peak, :func:`ehss.live.reference_band`).
    na, nb, nc, delay, method
        Structure of each channel's estimator: RELS of the paper (eqs (19)–(22)), sixth
        order. The drive is a known, broadband signal and the feedback nearly
        noise-free, where RELS follows a change of the rig faster than RML (about 2 s
        against 3 s on the simulated rig's +40 % payload) and a sixth-order model fits
        the heavier loop's resonance within the band.
    memory_s : float
        Memory of its forgetting, λ = 1 − 1/(memory_s fs): how fast the model follows
        the rig, against how much it scatters. The first estimator runs held by its
        bound of tr P (``p0``) on about nine samples in ten, which cancels the
        forgetting in the excited directions: its memory in steady running is set by
        that bound more than by λ (on the simulated rig, memories of 0.3 and 1 s gave
        its models the same error against the H1 estimate before a change, 1.2–1.3 %).
    p0 : float
        α of P(0) = α I, which also bounds tr P of the first estimator. Under a
        band-limited drive the directions of θ̂ that the drive does not excite wind P up
        to that bound within seconds, and from then on the bound's scaling holds every
        sample, which cancels the forgetting in the excited directions: that estimator
        scatters little but follows a change of the rig only in 2–2.5 s.
    tracker_trace_bound : float or None
        Bound of tr P of a second estimator of the same structure and memory (None: no
        second one): far above the equilibrium that its forgetting sets (tr P of
        about 3·10¹⁰ in the estimator's scaled units on the simulated rig), so that its
        forgetting acts and it follows a change within about its memory, with more
        scatter; bounded only so that P cannot overflow (its diagonal floor, 8 n eps
        tr P, stays below 0.03). Each judgement takes the model of the two that fits
        the latest ``guard.fit_s`` of feedback better in free run
        (:func:`ehss.compensation.adaptive.free_run_fit`).
    tracker_memory_s : float or None
        The tracker's memory (None: ``memory_s``). A longer memory of the first
        estimator with the tracker's kept short lowers the scatter of the models judged
        in steady running, but the first estimator then lags a change longer, and the
        choice between the two does not pick the tracker reliably meanwhile.
    follow_memory_s : float or None
        The first estimator's memory while it follows a change (``follow_s`` after a
        trigger; None: ``memory_s``, no switch): its forgetting factor switched to
        λ = 1 − 1/(follow_memory_s fs) at the trigger and back to ``memory_s``'s at the
        end of the follow (:meth:`ehss.RelsEstimator.set_forgetting`; variable
        forgetting with detection), so that a long ``memory_s`` need not slow the
        following. Measured with ``memory_s`` of 0.6, 1 and 1.5 s, the tracker's and
        this one 0.3 s, it did not bring the error after a +40 % payload change on the
        simulated rig closer to the level before (README, "Adaptive compensation"):
        not the default.
    trigger : TriggerSettings or None
        The quick test for a change of the loop on its tracking error
        (:class:`ehss.live.detect.TrackingTrigger`; None: none). It flags a change
        within a few tenths of a second, before any estimate of the loop moves; each
        trigger is logged (``"kind": "compensator_change"``) and makes the first
        estimator follow for ``follow_s``. A false trigger only speeds that estimator
        up for a while: the guards still decide what is sent. A rise dated to a load's
        fade-in, with the loop's model of before still matching the feedback, is
        undone instead (``"kind": "compensator_rollback"``;
        :meth:`ChannelAdapter.feed`).
    follow_s : float
        How long the first estimator follows after a trigger: its bound of tr P lifted
        to ``follow_trace_bound``, so that its forgetting acts as the tracker's does,
        and θ̂ averaged from the trigger on only; then P is set back to its value at
        the trigger (the gain of steady running) under its own bound. About the
        time the tracker needs to follow a change (0.75 s for a memory of 0.3 s) and
        a little more: longer, its models take up the scatter of the tracker's.
    follow_trace_bound : float
        The bound of tr P while following (as ``tracker_trace_bound``).
    correct_s : float
        For at most this long after a trigger, in preview mode, the running compensator
        is corrected instead of replaced: a short non-causal FIR ``K``
        (``correction_span`` taps each side) fitted to the data since the change
        (:func:`ehss.compensation.adaptive.fit_correction`) as soon as they suffice,
        and fitted again once the data under each correction suffice to check the next
        on; the full model is not judged meanwhile. The first correction refused (it
        does not halve the error left, or a guard fails) ends it, and the full model's
        inverse takes over as before. 0: no corrections.
    correction_span : int
        ``m`` of the correction: ``2 m + 1`` taps (2: a gain, a lead and a second
        derivative, and the two next terms).
    load_sigmas : float or None
        None: a model's compensator that would replace a corrected one (after a
        change) is loaded only if, on the rows the corrected one ran alone, it would
        have left no more tracking error; other loads are not compared. A number:
        every load is compared, on the rows since the latest change (since its first
        correction) in the H1 window, each compensator's feedback there changed as the
        new one would have changed it, and loaded only if it leaves at most
        ``1 + load_sigmas`` standard errors of that ratio of the error the running one
        left (:func:`ehss.compensation.adaptive.compare_compensators`; 2, one-sided,
        would refuse one in 44 models that are no worse if the ratio were Gaussian and
        its stretches independent; negative: a load must be better by that many). On
        the simulated rig that ratio on past rows does not foretell the ratio on the
        rows that follow (correlation 0.09 over 44 loads), and every margin measured
        (−2, 0, 2) made the tracking after a change worse (README, "Adaptive
        compensation"): not the default.
    h1_window_s : float or None
        Length of the sliding H1 estimate that must confirm a model (and of the recent
        reference the drive checks run on). A change of the rig shows in full in it
        after this long. None: :data:`H1_WINDOW_S`, or longer where the band is narrow
        (:meth:`h1_window_for`).
    update_s : float
        Period of each channel's judgements (stream time); the channels take their
        turns spread evenly over it.
    start_s : float
        First judgement (the estimator and the window need data first).
    adapt_until_s : float
        No update after this time (inf: always adapt); to compare with an inverse that
        is not adapted.
    alarm_after : int
        Consecutive refusals (of a channel that has a good compensator) that raise an
        alarm: one refusal is the guard doing its work on a scattered estimate; three
        (0.75 s at the default period) are a fault. A model that passes every guard
        but is kept out because the running compensator would leave less error, or
        that misses the H1 agreement only narrowly
        (:data:`ehss.compensation.adaptive.NEAR_MISS`; ``Decision.fault`` False), does
        not count. As many in a row before any compensator is loaded make the refits
        go without their record above the band until one is (:meth:`Judging.refine`).
    n_taps, max_sections : int
        The target's filter sizes (:data:`ehss.target.filter.MAX_TAPS`, ...).
    guard : UpdateGuard
    refine : bool or None
        Whether each model judged is first refitted to the output errors of the
        windows (:meth:`Judging.refine`): the output error of a model on the drive is
        the tracking error its inverse will leave, which the recursive estimator does
        not minimise. On the simulated rig it lowered the steady tracking error by
        11–13 % (18–31 % at the heavier payload), and on the 25 Hz servo it brought the
        error back to its level 2 s after +40 % mass (1.0–1.1× over [22, 24) s against
        1.7–3.1×; README, "Adaptive compensation"). It adds 7–20 ms to a judgement (1 to
        5 kHz; BENCHMARKS.md). None: on while channels × fs ≤ :data:`REFINE_LOAD`.
    judge_in : {"process", "thread", "stream"}
        Where judgements run: a worker process, a worker thread or the stream's own
        thread. A judgement (the model's checks, the H1 estimate, the inverse's design:
        milliseconds to tens of them) on the stream's thread holds up the samples; on a
        worker it does not: the stream's thread takes a copy of the windows and of θ̂
        at the channel's turn and the decision at the next channel's turn
        (``update_s`` / channels later), waiting for it only if the worker has not
        finished by then. That fixed point, in samples, makes a run the same wherever
        it is judged and whatever the machine's speed. A thread shares the
        interpreter's lock with the stream (the judgement's Python parts hold it for up
        to the switch interval, 5 ms); a process does not, and starts once per run
        (about a second; ``multiprocessing``'s spawn: a script that runs the loop needs
        ``if __name__ == "__main__":``).
    """

    mode: str = "preview"
    band_hz: tuple[float, float] | None = None
    method: str = "rels"
    na: int = 6
    nb: int = 5
    nc: int = 6
    delay: int = 1
    memory_s: float = 0.3
    p0: float = 1e6
    tracker_trace_bound: float | None = 1e12
    tracker_memory_s: float | None = None
    follow_memory_s: float | None = None
    average_s: float = 0.3
    trigger: TriggerSettings | None = field(default_factory=TriggerSettings)
    follow_s: float = 0.75
    follow_trace_bound: float = 1e12
    correct_s: float = 3.0
    correction_span: int = 2
    load_sigmas: float | None = None
    h1_window_s: float | None = None
    update_s: float = 0.25
    start_s: float = 2.0
    adapt_until_s: float = math.inf
    alarm_after: int = 3
    n_taps: int = 256
    max_sections: int = 16
    guard: UpdateGuard = field(default_factory=UpdateGuard)
    judge_in: str = "thread"
    refine: bool | None = None

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ParameterError(f"mode={self.mode!r} must be one of {MODES}")
        if self.judge_in not in JUDGE_IN:
            raise ParameterError(f"judge_in={self.judge_in!r} must be one of {JUDGE_IN}")
        for name in ("memory_s", "update_s"):
            check_real(getattr(self, name), name, lo=0.0, lo_open=True, unit="s")
        if self.h1_window_s is not None:
            check_real(self.h1_window_s, "h1_window_s", lo=0.0, lo_open=True, unit="s")
        check_real(self.follow_s, "follow_s", lo=0.0, unit="s")
        for name in ("tracker_memory_s", "follow_memory_s"):
            if getattr(self, name) is not None:
                check_real(getattr(self, name), name, lo=0.0, lo_open=True, unit="s")
        check_real(self.follow_trace_bound, "follow_trace_bound", lo=0.0, lo_open=True)
        check_real(self.correct_s, "correct_s", lo=0.0, unit="s")
        check_int(self.correction_span, "correction_span", lo=0)
        if self.load_sigmas is not None:
            check_real(self.load_sigmas, "load_sigmas")
        if self.refine not in (None, True, False):
            raise ParameterError(f"refine={self.refine!r} must be True, False or None "
                                 "(refit while the stream's load allows)")

    def h1_window_for(self, band_hz: tuple[float, float]) -> float:
        """The H1 window over ``band_hz``: ``h1_window_s`` if set, else
        :data:`H1_WINDOW_S` or, if longer, ``3 H1_BAND_POINTS / (hi − lo)``.

        The estimate's segments are a third of the window (:meth:`Judging.__call__`),
        so its points lie ``3 / window`` Hz apart: the longer window puts
        :data:`H1_BAND_POINTS` of them in the band. A reference of 0.2–5 Hz (the
        response of a structure to an earthquake, as hybrid simulation plays it) on the
        25 Hz servo at 2 kHz had two points in the band in 1.5 s, every model was
        refused for it, and the loop ran uncompensated (160 µm); over 5 s, 231 loads and
        16.8 µm. The simulated rig's 0.5–20 Hz asks 1.23 s, the loops' bands from 1 Hz
        less: 1.5 s for all of them, as before."""
        if self.h1_window_s is not None:
            return float(self.h1_window_s)
        lo, hi = band_hz
        return max(H1_WINDOW_S, 3.0 * H1_BAND_POINTS / max(hi - lo, 1e-12))

    def for_band(self, band_hz: tuple[float, float]) -> CompensationSettings:
        """These settings with ``h1_window_s`` set for ``band_hz``
        (:meth:`h1_window_for`), as a run records them."""
        return dataclasses.replace(self, h1_window_s=self.h1_window_for(band_hz))

    def for_stream(self, n_channels: int, fs: float) -> CompensationSettings:
        """These settings for a stream of ``n_channels`` at ``fs``: ``refine`` None
        becomes whether channels × fs ≤ :data:`REFINE_LOAD` (what the worker's share of
        a core allows), counted in windows of :data:`H1_WINDOW_S`: a refit's cost grows
        with its rows, and a longer window (``h1_window_s``, :meth:`for_band`) has
        more."""
        if self.refine is not None:
            return self
        window = H1_WINDOW_S if self.h1_window_s is None else self.h1_window_s
        return dataclasses.replace(
            self, refine=n_channels * fs * window / H1_WINDOW_S <= REFINE_LOAD)

    def to_dict(self) -> dict[str, Any]:
        return {"mode": self.mode, "band_hz": self.band_hz, "memory_s": self.memory_s,
                "h1_window_s": self.h1_window_s, "update_s": self.update_s,
                "start_s": self.start_s, "adapt_until_s": self.adapt_until_s,
                "n_taps": self.n_taps, "estimator": [self.na, self.nb, self.nc, self.delay,
                                                     self.method],
                "tracker_memory_s": self.tracker_memory_s,
                "follow_memory_s": self.follow_memory_s,
                "judge_in": self.judge_in, "follow_s": self.follow_s,
                "correct_s": self.correct_s, "correction_span": self.correction_span,
                "refine": self.refine,
                "load_sigmas": self.load_sigmas,
                "trigger": None if self.trigger is None else dataclasses.asdict(self.trigger),
                "min_interval_s": self.guard.min_interval_s,
                "crossfade_s": self.guard.crossfade_s, "max_gain": self.guard.max_gain}


class _Ring:
    """The latest ``size`` samples of a few signals."""

    def __init__(self, n_rows: int, size: int) -> None:
        self.buf = np.zeros((n_rows, size))
        self.fill = 0
        self.pos = 0

    def push(self, x: np.ndarray) -> None:
        size = self.buf.shape[1]
        n = x.shape[1]
        if n >= size:
            self.buf[:] = x[:, -size:]
            self.pos, self.fill = 0, size
            return
        idx = (self.pos + np.arange(n)) % size
        self.buf[:, idx] = x
        self.pos = (self.pos + n) % size
        self.fill = min(size, self.fill + n)

    def latest(self) -> np.ndarray:
        if self.fill < self.buf.shape[1]:
            return self.buf[:, :self.fill].copy()
        return np.roll(self.buf, -self.pos, axis=1)


@dataclass(frozen=True)
class Snapshot:
    """A channel's windows (drive, feedback, desired reference, oldest first) and its
    averaged θ̂ (estimator's, then tracker's; shape (1 or 2, n_params)) at one time;
    while a change is corrected, the compensator corrected and the spans of the windows
    since the change, each with the correction that ran then (``spans`` of
    :func:`~ehss.compensation.adaptive.fit_correction`; empty: judge the model); the
    compensator that runs, and the spans of the windows that each compensator ran
    alone since the latest change (``spans`` of
    :func:`~ehss.compensation.adaptive.compare_compensators`); the first sample of the
    windows since the latest change of the loop (0: it came before them); whether the
    refits go without their record above the band, and then the latest model refitted
    and not loaded, where the next refit goes on from (:meth:`Judging.refine`); the
    channel's usual residual on fresh data and the reference's usual RMS over the
    window (the medians over its recent loads; None before :data:`RESIDUAL_LOADS` of
    them: :meth:`AdaptiveCompensator._judge_fit`, :meth:`Judging._quiet`); how far its
    models usually miss the H1 estimate (:data:`USUAL_DISAGREEMENT`)."""

    drive: np.ndarray
    feedback: np.ndarray
    desired: np.ndarray
    thetas: np.ndarray
    running: CompensatorDesign | None = None
    spans: tuple = ()
    current: CompensatorDesign | None = None
    ran: tuple = ()
    fresh: int = 0
    running_model: ehss.ArmaxModel | None = None
    unanchored: bool = False
    refitted: ehss.ArmaxModel | None = None
    residual_floor: float | None = None
    reference_level: float | None = None
    disagreement: tuple[float, float] | None = None


class ChannelAdapter:
    """Estimator, sliding windows and adaptive compensator of one channel.

    Parameters
    ----------
    name : str
    fs : float
    band_hz : (lo, hi)
    scale : float
        RMS of the channel's reference (the estimator's scale of u and y).
    settings : CompensationSettings
    loop : str, optional
    params : RigParams, optional
        With ``loop``: the rig whose limits the drive must respect.
    preview : int
        The target filter's preview (the compensators' preview in preview mode).
    """

    def __init__(self, name: str, fs: float, band_hz: tuple[float, float], scale: float,
                 settings: CompensationSettings, *, loop: str | None = None,
                 params: Any = None, preview: int = 0) -> None:
        s = settings
        self.name = name
        self.fs = float(fs)
        self.settings = s
        self._scale = scale
        self.estimator = self._new_estimator(None)
        # the tracker: the same estimator with its forgetting not held by the trace bound
        self.tracker = None if s.tracker_trace_bound is None \
            else self._new_estimator(None, trace_bound=s.tracker_trace_bound,
                                     memory_s=s.tracker_memory_s)

        self.window = _Ring(3, max(64, int(round(s.h1_window_for(band_hz) * self.fs))))
        self.compensator = AdaptiveCompensator(
            self.fs, band_hz, mode=s.mode, preview=preview if s.mode == "preview" else None,
            n_taps=s.n_taps, max_sections=s.max_sections, guard=s.guard, loop=loop,
            params=params)
        self.alarm = False
        self.refusals = 0
        # the fresh residuals of loads that fitted as the guard asks, and the
        # reference's RMS over their windows (Snapshot)
        self._residuals: collections.deque[float] = collections.deque(maxlen=RESIDUAL_LOADS[1])
        self._levels: collections.deque[float] = collections.deque(maxlen=RESIDUAL_LOADS[1])
        # the H1 disagreements of judgements that were no fault (Snapshot)
        self._misses: collections.deque[tuple[float, float]] = collections.deque(
            maxlen=USUAL_JUDGEMENTS[1])
        self.busy_until = 0
        self._n = 0
        self._n_average = int(round(s.average_s * self.fs))
        self._thetas: collections.deque = collections.deque()
        self.chosen = "estimator"
        self.judging = Judging(self.fs, s, self.compensator)
        self.trigger = None if s.trigger is None else TrackingTrigger(self.fs, s.trigger)
        self._trace_bound = self.estimator.settings.trace_bound
        self._follow_until: int | None = None
        self._steady_P = self.estimator.P
        # a change being corrected until _correct_until: the compensator corrected, and
        # from which sample each correction ran ([from, taps], None: uncorrected)
        self._correct_until = 0
        self._base: CompensatorDesign | None = None
        self._spans: list[list] = []
        self._accepted_taps: np.ndarray | None = None
        # each compensator sent and the sample from which it ran alone, since the
        # latest change (from sample _since); the sample from which a corrected one
        # runs alone (None: the one running is not corrected)
        self._ran: list[tuple[int, CompensatorDesign]] = []
        self._since = 0
        self._corrected_from: int | None = None
        # the sample from which the loop is as it is now (its latest change)
        self._changed_at = 0
        # the latest model refitted while no compensator ran, not loaded
        self._refitted: ehss.ArmaxModel | None = None
        # the compensator sent last, and the one before it (None: none yet)
        self._running: CompensatorDesign | None = None
        self._running_model: ehss.ArmaxModel | None = None
        self._before: CompensatorDesign | None = None
        # the latest loads of a model's inverse that may still be undone, oldest first
        self._undoable: list[_Load] = []
        # the latest load fades in from sample busy_from to busy_until
        self.busy_from = 0
        #: a load to undo (the trigger dated its rise to that load's fade-in), for the
        #: loop to send the compensator before it again (:meth:`rolled_back`)
        self.undo: _Load | None = None
        #: at the latest change flagged, the apply index of the load it came with
        #: (None: none), when the model's prediction errors told it from that load's
        self.change_at_load: int | None = None
        # the sample a change flagged at a load began at, by the model's output errors
        self._began: int | None = None
        #: the sample the latest change was flagged at (-1: none)
        self.flagged_at = -1

    def _forgetting(self, memory_s: float | None) -> float:
        """λ = 1 − 1/(memory fs) of a memory (None: ``memory_s``)."""
        memory = self.settings.memory_s if memory_s is None else memory_s
        return 1.0 - 1.0 / (memory * self.fs)

    def _new_estimator(self, theta0: np.ndarray | None, *, trace_bound: float | None = None,
                       memory_s: float | None = None) -> ehss.RelsEstimator:
        s = self.settings
        return ehss.RelsEstimator(
            na=s.na, nb=s.nb, nc=s.nc, delay=s.delay, method=s.method, theta0=theta0, p0=s.p0,
            trace_bound=trace_bound, forgetting=self._forgetting(memory_s),
            dt=1.0 / self.fs,
            u_scale=self._scale, y_scale=self._scale)

    def feed(self, drive: np.ndarray, feedback: np.ndarray, desired: np.ndarray) -> bool:
        """Consecutive samples of the drive (model input), feedback and desired
        reference; True if the trigger flagged a change of the loop in them. A rise
        that is the latest loads' (:meth:`_load_that_rose`) is not a change: it is left
        in :attr:`undo` for the loop to roll back."""
        self.estimator.update_many(drive, feedback)
        if self.tracker is not None:
            self.tracker.update_many(drive, feedback)
        self.window.push(np.vstack([drive, feedback, desired]))
        self._n += drive.size
        if self._follow_until is not None and self._n >= self._follow_until:
            self._end_follow()
        thetas = [self.estimator.theta]
        if self.tracker is not None:
            thetas.append(self.tracker.theta)
        self._thetas.append((self._n, np.array(thetas)))
        while self._thetas and self._thetas[0][0] < self._n - self._n_average:
            self._thetas.popleft()
        changed = self.trigger is not None and self.trigger(desired - feedback)
        if changed:
            self._began = None
            self.undo = self._load_that_rose()
            changed = self.undo is None
        if changed:
            self.follow_change(None if self._began is None
                               else (self._n - self._began) / self.fs)
        return changed

    def _load_that_rose(self) -> _Load | None:
        """The load whose rise of the error the trigger just flagged, if it is one of
        the latest: its first block 2σ above the learnt level
        (:data:`~ehss.live.detect.ONSET_Z`; every block before it, from the CUSUM's last
        zero, below) is the one in which that load began to fade in, or a later one up
        to the first block after its fade-in. A rise flagged on the level held since an
        undoing (in the blocks right after it), or already there in the first block the
        test took (:attr:`~ehss.live.detect.TrackingTrigger.onset_censored`), is a
        change of the loop."""
        trigger = self.trigger
        self.change_at_load = None
        if trigger is None or trigger.held or trigger.onset_censored:
            # a rise already there when the test began cannot be dated to a load
            return None
        block = int(round(trigger.settings.block_s * self.fs))
        for load in reversed(self._undoable):
            if load.apply_index - block < trigger.onset_index <= load.until + block:
                if self._loop_unchanged(load, trigger.onset_index, block):
                    return load
                self.change_at_load = load.apply_index
                self._began = self._change_began(load, trigger.onset_index, block)
                return None
        return None

    def _loop_unchanged(self, load: _Load, onset: int, block: int) -> bool:
        """Whether the model the compensator before ``load`` was designed from, run
        on the drive, matches the feedback as well since the rise (sample ``onset``) as
        before the load, in blocks of ``block`` samples.

        Its output errors y − (q^{-d} B/A) u (:class:`~ehss.live.detect.BaselineResidual`
        with C = A) do not depend on the compensator (the drive is measured), while a
        change of the loop raises them about as much as the tracking error (the
        one-step prediction errors, with the past feedback in them, barely: on the servo
        +40 % mass raised them 1.3× in √(median ε²), the output errors 7.2×, the
        tracking error 7.1×). They are compared
        in the trigger's blocks (ln median ε²): the loop changed if their mean since the
        rise is :data:`~ehss.live.detect.ONSET_Z` standard errors or more above that
        before the load (from the standard deviation of the blocks before; one-sided, a
        loop that did not change is taken for a changed one in about 1 rise in 25 with
        about 14 blocks before a load: Student's t). The blocks before are those of the
        window when the load was sent (:attr:`_Load.before`, the 1.5-s window's blocks
        but its first, all of them older than the load's fade-in), not those the
        window still holds when the rise is flagged: a second after the load, those are
        few, and a change that came just before the load is among them (−30 % payload
        on the rig 0.2 s before a load was rolled back so, 4 blocks before against 10
        since, and followed only 2 s after it). With fewer than three blocks before the
        load the timing alone decides."""
        model = load.model
        if model is None or load.before is None:
            return True
        u, y, _ = self.window.latest()
        first = self._n - self.window.fill
        after = _output_error_levels(model, u, y, onset - first, self._n - first, block)
        before = load.before
        if before.size < 3 or not after.size:
            return True
        spread = float(np.std(before, ddof=1)) * math.sqrt(1 / before.size + 1 / after.size)
        return float(np.mean(after) - np.mean(before)) < ONSET_Z * spread

    def _change_began(self, load: _Load, onset: int, block: int) -> int:
        """The sample a change flagged at ``load`` began at, by the output errors of the
        model before it (:meth:`_loop_unchanged`), which the load does not move: the
        least-squares change point of their level in the window's blocks (Hinkley's
        estimate of one shift of the mean: the split that maximises
        k (m − k) / m · (x̄_after − x̄_before)², the level rising), no later than the
        trigger's onset (``onset``, dated by the tracking error, which the load's
        fade-in moves too). On the rig, −30 % payload dated by the trigger to a load
        0.7 s after it came was dated here to its own block; from the later date the
        first correction waited 0.7 s longer for its rows (1.96× the level before over
        [22, 24) s against 0.75×, the rig's noise seed 1)."""
        assert load.model is not None
        u, y, _ = self.window.latest()
        first = self._n - self.window.fill
        x = _output_error_levels(load.model, u, y, 0, self._n - first, block,
                                 finite=False)
        # block i (from 0) holds samples first + (i + 1) block ... first + (i + 2) block
        last = min(x.size, (onset - first) // block)   # splits before the onset's block
        best, began = 0.0, onset
        m = x.size
        for k in range(2, last):
            a, b = x[:k], x[k:]
            if not (np.isfinite(a).all() and np.isfinite(b).all()):
                continue
            gain = float(np.mean(b) - np.mean(a))
            score = k * (m - k) / m * gain * gain
            if gain > 0.0 and score > best:
                best, began = score, first + (k + 1) * block
        return min(began, onset)

    def _levels_now(self, model: ehss.ArmaxModel | None) -> np.ndarray | None:
        """The trigger's block statistic of ``model``'s output errors over the window
        as it is (:meth:`_loop_unchanged`; None without a trigger or a model)."""
        if self.trigger is None or model is None:
            return None
        u, y, _ = self.window.latest()
        block = int(round(self.trigger.settings.block_s * self.fs))
        return _output_error_levels(model, u, y, 0, u.size, block)

    def follow_change(self, onset_s: float | None = None) -> None:
        """The loop changed (a trigger): the estimator follows quickly for
        ``follow_s``, and θ̂ is averaged from here on only. The change began
        ``onset_s`` before (default: the trigger's
        :attr:`~ehss.live.detect.TrackingTrigger.onset_s`).

        Its bound of tr P is lifted to ``follow_trace_bound`` (its forgetting then
        acts, as the tracker's does), and at the end P is set back to the one it had
        here, the gain of its steady running, with its own bound.
        """
        while len(self._thetas) > 1:  # the newest stays: a snapshot needs one
            self._thetas.popleft()
        if onset_s is None:
            onset_s = 0.0 if self.trigger is None else self.trigger.onset_s
        self.flagged_at = self._n
        self._since = self._n - int(round(onset_s * self.fs))
        self._changed_at = self._since
        est = self.estimator
        if self._follow_until is None:
            self._steady_P = est.P
        est.set_trace_bound(self.settings.follow_trace_bound)
        est.set_forgetting(self._forgetting(self.settings.follow_memory_s))
        self._follow_until = self._n + int(round(self.settings.follow_s * self.fs))
        if self.settings.mode == "preview":
            # the data since the change began (the trigger's estimate of it) and no more
            # than its blocks held
            self._correct_until = self._n + int(round(self.settings.correct_s * self.fs))
            self._base = self.compensator.current
            since = self._n - int(round(onset_s * self.fs))
            # the compensator sent last may not have run from the change on: the rows
            # before it took over ask for the one before it
            if self.busy_until <= since:
                self._spans = [[since, None]]
            else:
                self._spans = [[self.busy_until, None]] if self._before is None \
                    else [[since, self._before], [self.busy_until, None]]

    def spans(self) -> tuple:
        """While a change is corrected, the spans of the windows since it (window
        indices ``start, stop`` and the correction that ran; empty otherwise). The
        cross-fade into each correction belongs to none."""
        if self._n >= self._correct_until or self._base is None:
            return ()
        first = self._n - self.window.fill
        fade = int(round(self.settings.guard.crossfade_s * self.fs))
        out = []
        for k, (n_from, taps) in enumerate(self._spans):
            n_to = self._spans[k + 1][0] - fade if k + 1 < len(self._spans) else self._n
            a, b = max(n_from, first) - first, min(n_to, self._n) - first
            if b > a:
                out.append((a, b, taps))
        return tuple(out)

    def ready(self) -> bool:
        """Whether a judgement may be made now: while a change is corrected, once
        enough samples are in for a correction, and enough under the latest one to
        check the next on, or enough since the change to refit the model
        (:meth:`Judging.refine`)."""
        spans = self.spans()
        if not spans:
            return self._n >= self._correct_until
        if self._correction_ready(spans):
            return True
        # the refit waits for the first correction, which it is judged against
        # (:meth:`Judging._better`), while the rows since the change are still too few
        # for one
        first = not any(isinstance(then, np.ndarray) for _, then in self._spans)
        filling = self._n - self._changed_at < self.judging.correction_rows
        return self._refit_ready() and not (first and filling)

    def _correction_ready(self, spans: tuple) -> bool:
        j = self.judging
        return sum(b - a for a, b, _ in spans) >= j.correction_rows \
            and spans[-1][1] - spans[-1][0] >= j.correction_rows - j.n_fit \
            and self._spans[-1][0] <= self._n

    def _refit_ready(self) -> bool:
        """Whether the rows since the latest change suffice to refit the model (after
        the start-up from the state the change left the loop in, as the running model
        has it: :meth:`Judging.refine`)."""
        return self.settings.refine is not False and self._n - self._changed_at \
            >= self.judging.rows_to_refit(self.compensator.current_model)

    def started(self, until: int, apply_index: int | None = None) -> None:
        """The compensator just accepted is sent: it fades in from sample
        ``apply_index`` (default: a cross-fade before ``until``) and runs alone from
        sample ``until`` (the end of its shadow run and cross-fade)."""
        if apply_index is None:
            apply_index = until - max(1, int(round(self.settings.guard.crossfade_s * self.fs)))
        before = self._running
        # a model's inverse that replaced another may be undone, a correction not; the
        # rise of the error a load causes is flagged within a second (a few blocks)
        if self._accepted_taps is not None:
            self._undoable = []
        elif before is not None and before is not self.compensator.current:
            self._undoable = self._undoable[-2:] + [
                _Load(apply_index, until, before, self._running_model,
                      self._levels_now(self._running_model))]
        self._running_model = self.compensator.current_model
        if before is None and self.trigger is not None:
            # the first compensator takes over: the error falls tens of times, and the
            # blocks before it would widen the level the trigger tests against (a
            # change 6 s after the first load was flagged only 2.4 s after it came)
            self.trigger.restart(until - self._n)
        self.busy_from, self.busy_until = apply_index, until
        self._corrected_from = None if self._accepted_taps is None else until
        if self.compensator.current is not None:
            self._ran.append((until, self.compensator.current))
        if self._accepted_taps is not None:
            if not any(isinstance(then, np.ndarray) for _, then in self._spans):
                # the first correction after a change: later models are compared on the
                # rows the corrected compensators ran alone (the error under the one
                # corrected, the change's own, many times larger, would outweigh them)
                self._since = until
            self._spans.append([until, self._accepted_taps])
            if self.settings.refine is not False:
                # the refitted model takes over from here (it is compared with the
                # correction on the rows the correction runs alone)
                self._correct_until = 0
        elif self._n < self._correct_until and all(
                not isinstance(then, np.ndarray) for _, then in self._spans):
            # a model judged before the change was flagged: the correction corrects it,
            # the rows before ask for the one it replaces
            self._spans = [[n, self._base if then is None else then]
                           for n, then in self._spans] + [[until, None]]
            self._base = self.compensator.current
        else:
            self._correct_until = 0   # a full model's inverse: the correction is over
        self._before = self._running
        self._running = self.compensator.current

    def rolled_back(self, apply_index: int, until: int) -> None:
        """The compensator that ran before the load of :attr:`undo` is sent again and
        fades in from sample ``apply_index`` to ``until``: it is the running one again
        (any load sent since is superseded), no load before it can be undone any more,
        and the trigger goes on against the level it learnt before the rise
        (:meth:`~ehss.live.detect.TrackingTrigger.rearm`), from ``until`` on."""
        load = self.undo
        assert load is not None
        self.undo = None
        self._undoable = []
        self.compensator.current = load.design
        self.compensator.current_model = load.model
        self.busy_from, self.busy_until = apply_index, until
        self._ran.append((until, load.design))
        self._running, self._running_model, self._before = load.design, load.model, None
        if self.trigger is not None:
            self.trigger.rearm(until - self._n)

    def _end_follow(self) -> None:
        self._follow_until = None
        self.estimator.set_trace_bound(self._trace_bound)
        self.estimator.set_forgetting(self._forgetting(None))
        self.estimator.set_covariance(self._steady_P)

    def snapshot(self) -> Snapshot:
        """What a judgement needs, copied: the windows and θ̂ averaged over the last
        ``average_s`` (one estimate per block fed), which halves its scatter at the cost
        of that much more lag. Later samples do not change it."""
        u, y, r = self.window.latest()
        spans = self.spans()
        if spans and not self._correction_ready(spans) and self._refit_ready():
            spans = ()   # the refitted model before a correction
        fresh = max(0, self._changed_at - (self._n - self.window.fill))
        unanchored = self.compensator.current is None \
            and self.refusals >= self.settings.alarm_after
        floor = level = None
        if len(self._residuals) >= RESIDUAL_LOADS[0]:
            floor, level = float(np.median(self._residuals)), float(np.median(self._levels))
        usual = None
        if len(self._misses) >= USUAL_JUDGEMENTS[0]:
            q = np.quantile(np.array(self._misses), USUAL_DISAGREEMENT, axis=0)
            usual = (float(q[0]), float(q[1]))
        return Snapshot(u, y, r, np.mean([t for _, t in self._thetas], axis=0),
                        self._base if spans else None, spans, self.compensator.current,
                        self._ran_spans(), fresh, self.compensator.current_model,
                        unanchored, self._refitted if unanchored else None, floor, level,
                        usual)

    def _ran_spans(self) -> tuple:
        """The spans of the windows (indices ``start, stop``) that each compensator
        ran alone since the latest change, with it (None: the one running now); the
        cross-fades belong to none."""
        first = self._n - self.window.fill
        fade = int(round(self.settings.guard.crossfade_s * self.fs))
        # the compensators that ran only before the window are of no more use
        while len(self._ran) > 1 and self._ran[1][0] - fade <= first:
            self._ran.pop(0)
        if self.settings.load_sigmas is None:
            # only a corrected compensator's own rows
            if self._corrected_from is None or self._corrected_from >= self._n:
                return ()
            return ((max(0, self._corrected_from - first), self._n - first, None),)
        out = []
        for k, (n_from, design) in enumerate(self._ran):
            last = k + 1 == len(self._ran)
            n_to = self._n if last else self._ran[k + 1][0] - fade
            a, b = max(n_from, first, self._since), min(n_to, self._n)
            if b > a:
                out.append((a - first, b - first, None if last else design))
        return tuple(out)

    def models(self, snapshot: Snapshot | None = None) -> list[ehss.ArmaxModel]:
        """The estimator's model, and the tracker's if there is one, of ``snapshot``
        (default: now)."""
        return self.judging.models((self.snapshot() if snapshot is None else snapshot).thetas)

    def model(self, u: np.ndarray | None = None, y: np.ndarray | None = None, *,
              snapshot: Snapshot | None = None) -> ehss.ArmaxModel:
        """The model judged: of :meth:`models`, the one whose free-run simulation on
        the drive ``u`` fits the latest ``guard.fit_s`` of the feedback ``y`` better
        (the estimator's when no window is given)."""
        snap = self.snapshot() if snapshot is None else snapshot
        model, self.chosen = self.judging.model(snap.thetas, u, y)
        return model

    def judge(self, t_s: float, snapshot: Snapshot | None = None) -> Decision:
        """The decision on the model of ``snapshot`` (default: now) at stream time
        ``t_s``, recorded in the compensator's log."""
        verdict = self.judging(t_s, self.snapshot() if snapshot is None else snapshot)
        self.take(verdict)
        return verdict.decision

    def take(self, verdict: Verdict) -> None:
        """Record a judgement made elsewhere (:class:`Judging`) as :meth:`judge` does."""
        self._accepted_taps = None
        if verdict.chosen == "correction":
            # the model stays: the compensator of its inverse runs corrected
            self.compensator.record(verdict.decision, self.compensator.current_model)
            self.chosen = verdict.chosen
            if verdict.decision.accepted:
                self._accepted_taps = np.asarray(verdict.decision.figures["correction_taps"])
            else:
                # nothing (more) to correct: the full model's inverse takes over
                self._correct_until = 0
            return
        self.compensator.record(verdict.decision, verdict.model)
        if verdict.model is not None:
            self.chosen = verdict.chosen
        figures = verdict.decision.figures
        if "h1_phase_deg" in figures and not (verdict.decision.fault
                                              and not verdict.decision.accepted):
            self._misses.append((float(figures["h1_magnitude_db"]),
                                 float(figures["h1_phase_deg"])))
        if verdict.decision.accepted:
            self._refitted = None
            if "fresh_rows" in figures and self.spans():
                self._correct_until = 0   # refitted since the change: no more corrections
            if "quiet" not in figures and math.isfinite(figures.get("fresh_residual_rms",
                                                                    math.inf)) \
                    and "reference_rms" in figures:
                self._residuals.append(float(figures["fresh_residual_rms"]))
                self._levels.append(float(figures["reference_rms"]))
        elif "refit_rows" in figures and self.compensator.current is None:
            self._refitted = verdict.model     # Snapshot.refitted


@dataclass(frozen=True)
class _Load:
    """A load of a model's inverse that may be undone: it faded in from sample
    ``apply_index`` to ``until``; ``design`` (with its ``model``) ran before it, and
    ``before`` holds the trigger's block statistic of that model's output errors over
    the window when the load was sent (None: no model or no trigger)."""

    apply_index: int
    until: int
    design: CompensatorDesign
    model: ehss.ArmaxModel | None
    before: np.ndarray | None = None


def _output_error_levels(model: ehss.ArmaxModel, u: np.ndarray, y: np.ndarray,
                         start: int, stop: int, block: int, *,
                         finite: bool = True) -> np.ndarray:
    """ln median ε² (:func:`~ehss.live.detect.block_statistic`) of the output errors
    y − (q^{-d} B/A) u of ``model``, run on the window ``u, y`` from its first sample, in
    blocks of ``block`` from ``start`` to ``stop`` (the first block, which holds the
    simulation's start, left out); the finite ones only, unless ``finite`` is False."""
    eps = BaselineResidual(model.a, model.b, model.a, model.delay)(u, y)
    x = np.array([block_statistic(eps[i:i + block])
                  for i in range(max(start, block), stop - block + 1, block)])
    return x[np.isfinite(x)] if finite else x


@dataclass(frozen=True)
class Verdict:
    """A judgement: the decision, the model judged (None if there was none) and whose
    model it is (``"estimator"`` or ``"tracker"``; ``"correction"`` for a correction of
    the running compensator, with no model)."""

    decision: Decision
    model: ehss.ArmaxModel | None
    chosen: str


class Judging:
    """How a channel's snapshot is judged; changes nothing, so that it can run on a
    worker thread or in a worker process (a copy) while the stream is fed.

    Parameters
    ----------
    fs : float
    settings : CompensationSettings
    compensator : AdaptiveCompensator
        Whose :meth:`~AdaptiveCompensator.assess` decides (its state is not touched).
    """

    def __init__(self, fs: float, settings: CompensationSettings,
                 compensator: AdaptiveCompensator) -> None:
        self.fs = float(fs)
        self.settings = settings
        self.compensator = compensator
        lo, hi = compensator.band_hz
        n_taps = 2 * settings.correction_span + 1
        # a correction's fit: four times as many independent samples as taps, a record
        # of T s in a band of B Hz holding about 2 B T of them; then the guard's fresh
        # stretch to check it on, and a period of the upper edge where the zero-phase
        # filter's end is not settled
        self.n_fit = int(math.ceil(4 * n_taps * self.fs / (2.0 * (hi - lo))))
        self._n_check = max(1, int(round(settings.guard.fit_s * self.fs)))
        self.correction_rows = self.n_fit + self._n_check + int(math.ceil(self.fs / hi))
        # a load's check: stretches that hold about four independent samples of the band
        self._n_chunk = int(math.ceil(4 * self.fs / (2.0 * (hi - lo))))
        #: rows since a change that a refit of the model needs (:meth:`refine`)
        self.refine_rows = self._refine_rows(settings.na + settings.nb + 1)

    def models(self, thetas: np.ndarray) -> list[ehss.ArmaxModel]:
        """The models of averaged θ̂ (rows: estimator, tracker)."""
        s = self.settings
        return [ehss.ArmaxModel(a=np.r_[1.0, th[:s.na]], b=th[s.na:s.na + s.nb + 1],
                                c=np.r_[1.0, th[s.na + s.nb + 1:]], delay=s.delay,
                                dt=1.0 / self.fs) for th in thetas]

    def model(self, thetas: np.ndarray, u: np.ndarray | None, y: np.ndarray | None
              ) -> tuple[ehss.ArmaxModel, str]:
        """Of :meth:`models`, the one that fits the latest ``guard.fit_s`` of ``y`` better
        in free run on ``u``, and whose it is."""
        models = self.models(thetas)
        if u is None or y is None or len(models) == 1:
            return models[0], "estimator"
        n_fit = max(1, min(int(round(self.settings.guard.fit_s * self.fs)), u.size // 2))
        best = int(np.argmax([free_run_fit(m, u, y, n_fit) for m in models]))
        return models[best], ("estimator", "tracker")[best]

    def refine(self, model: ehss.ArmaxModel, u: np.ndarray, y: np.ndarray, fresh: int = 0,
               also: ehss.ArmaxModel | None = None, *, prior: bool = True,
               then: ehss.ArmaxModel | None = None) -> tuple[ehss.ArmaxModel, int]:
        """``model``'s dynamics refitted to the windows' output errors, and the rows
        it was refitted on (0: not refitted).

        The tracking error a compensator C' = M⁻¹ will leave is (M − G) M⁻¹ r, and
        M⁻¹ r is the drive it gives: it is the output error y − M u of M on that
        drive, which the recursive estimator does not minimise (its one-step
        prediction errors weight the band by its noise model; the bias of a sixth-order
        model of a higher-order, nonlinear loop falls where that weight is low). So
        the model, as a start, is refitted by output-error minimisation
        (:func:`ehss.identification.oe_pem`) on the rows since the loop's latest
        change (``fresh``, the rows before only run it from rest) or since the model's
        own start-up from rest has died out (:func:`_start_up`), whichever is later,
        if they hold :data:`REFINE_SAMPLES` independent samples of the band per
        parameter, with a record of the start above the band (:meth:`_prior`; not with
        ``prior`` False, below). It starts from ``model`` and from ``also`` (the model
        of the compensator that runs): of the starts and their refits, the one that
        fits those rows best in free run is returned; ``model`` if none does better or
        the fit fails. An unstable start is none (its start-up never dies out). The
        refit's poles stay within the radius whose modes die out (e⁻⁷) within half the
        rows: slower ones are not determined by them.

        The record holds a refit to its start above the band, and near the band's top
        (whose response the start's structure ties to the one above it). A channel on
        which no compensator runs yet and whose latest judgements were all refused as
        faults (``alarm_after`` of them: :attr:`Snapshot.unanchored`) has no start that
        an H1 estimate has confirmed, and where the recursive estimate misses the loop
        the record holds every refit to that miss: the 4 kHz specimen under a
        reference rolled off by a second-order filter, whose 20-dB band reaches over
        its resonance, had models 2–3 dB / 20–35° off there and was never compensated
        (550–790 µm). There the refits go without it until a compensator is loaded,
        and start from ``then`` as well (the latest refit that was not loaded): their
        few evaluations each go on where the last stopped, instead of starting again
        from the same estimate (first loads at 2.9–3.75 s on four pairs of references,
        against 3.5–9.9 s)."""
        s = self.settings
        starts = [m for m in (model, also, then) if m is not None and m.is_stable()
                  and m.a.size == s.na + 1 and m.b.size == s.nb + 1]
        if s.refine is False or not starts:
            return model, 0
        settle = min(_start_up(m) for m in starts)
        # from rest, or from the state the change left the loop in: the rows that hold
        # the response to the loop as it was die out as a start-up does
        start = int(fresh) + settle if fresh else settle
        n = u.size - start
        if n < self.refine_rows:
            return model, 0
        radius = math.exp(-SETTLE_TIME_CONSTANTS / (0.5 * n))
        best, score = model, free_run_fit(model, u, y, n)
        for m in starts:
            try:
                fit = oe_pem(u, y, nf=s.na, nb=s.nb, delay=s.delay, dt=1.0 / self.fs,
                             theta0=np.r_[m.a[1:], m.b], first=start,
                             records=[self._prior(m, n, u[start:])] if prior else [],
                             max_nfev=REFINE_EVALUATIONS, radius=radius)
            except EhssError:
                continue
            fit_score = free_run_fit(fit, u, y, n)
            if fit_score > score:
                best, score = fit, fit_score
        return best, 0 if best is model else n

    def _prior(self, prior: ehss.ArmaxModel, n: int, drive: np.ndarray) -> tuple:
        """A record of ``prior`` for a refit of ``n`` rows of ``drive``
        (``records`` of :func:`ehss.identification.oe_pem`): its response to white
        noise with nothing below the band's upper edge. The drive is band-limited, so
        the rows say nothing of the loop above the band, where a refit alone puts sharp
        features that the target's filter cannot realise: there the prior rules,
        weighted to say as much as the rows do (weight² × its power = the rows' power
        of the drive), and it says nothing in the band. The noise is
        :data:`PRIOR_LENGTH` times as long as the prior's own start-up or its
        parameters, and no longer than the rows."""
        hi = self.compensator.band_hz[1]
        length = min(n, PRIOR_LENGTH * max(_start_up(prior), prior.a.size + prior.b.size))
        spectrum = np.fft.rfft(np.random.default_rng(PRIOR_SEED).standard_normal(length))
        spectrum[np.fft.rfftfreq(length, 1.0 / self.fs) <= hi] = 0.0
        noise = np.fft.irfft(spectrum, length)
        noise *= float(np.sqrt(np.mean(drive ** 2))) / max(float(np.std(noise)), 1e-300)
        return noise, prior.simulate(noise), math.sqrt(n / length)

    def _h1(self, model: ehss.ArmaxModel, u: np.ndarray, y: np.ndarray, fresh: int
            ) -> FrequencyResponse:
        """The H1 estimate of the loop as it is now that ``model`` is judged against:
        over the rows since its latest change (``fresh`` on), in segments of a third of
        them (a power of two: 4 averages with half overlap).

        Since a change, the segments are short (256 samples at 1 kHz 0.75 s after it)
        and their points are biased where the loop lags or the drive's spectrum ends
        within a bin: each segment of the feedback is read as late as it lags the drive
        (``delay="auto"``), and each point is compared with the model as the estimate
        sees it (:func:`seen_alike`). On a 12 Hz loop behind two samples of delay, the
        model refitted 0.75 s after +40 % mass was refused 16.4° off at the band's top
        (0.3° as the estimate sees the model), and the error took 2.5–3 s to come
        back (1.26–1.43× its level before over [2, 4) s after the change now). In steady
        running the estimate is taken as it is: a refusal there keeps a compensator that
        tracks well, and taken out there too, the bias let in models that the rig's
        guard had refused, with no better tracking over 24 runs after +40 % payload
        (README, "Adaptive compensation")."""
        uh, yh = u[fresh:], y[fresh:]
        nper = min(int(2 ** round(math.log2(max(16, uh.size / 3)))), uh.size)
        if not fresh:
            return ehss.h1_estimate(uh, yh, fs=self.fs, nperseg=nper)
        h1 = ehss.h1_estimate(uh, yh, fs=self.fs, nperseg=nper, delay="auto")
        return seen_alike(model, h1, u, fresh)

    def rows_to_refit(self, running: ehss.ArmaxModel | None) -> int:
        """Rows since a change that a refit needs: :attr:`refine_rows` after the
        start-up of the ``running`` model (:meth:`refine`)."""
        return self.refine_rows + (0 if running is None or not running.is_stable()
                                   else _start_up(running))

    def _refine_rows(self, n_params: int) -> int:
        lo, hi = self.compensator.band_hz
        return int(math.ceil(REFINE_SAMPLES * n_params * self.fs / (2.0 * (hi - lo))))

    def correct(self, t_s: float, snap: Snapshot) -> Verdict:
        """The correction of the running compensator fitted to the fresh samples of
        ``snap``, judged (:meth:`AdaptiveCompensator.assess_correction`)."""
        comp = self.compensator
        try:
            corr = fit_correction(snap.desired, snap.feedback, fs_hz=self.fs,
                                  band_hz=comp.band_hz, spans=snap.spans,
                                  n_check=self._n_check,
                                  half_span=self.settings.correction_span,
                                  base=snap.running)
        except EhssError as exc:
            return Verdict(Decision(t_s, False, f"no correction: {exc}"), None, "correction")
        return Verdict(comp.assess_correction(t_s, corr, snap.running, snap.desired), None,
                       "correction")

    def __call__(self, t_s: float, snap: Snapshot) -> Verdict:
        quiet = self._quiet(snap)
        if quiet:
            return Verdict(Decision(t_s, False, quiet, fault=False), None, "")
        u = snap.drive
        fresh = snap.fresh if self.settings.refine is not False else 0
        if snap.spans:
            corrected = self.correct(t_s, snap)
            if fresh and u.size - fresh >= self.rows_to_refit(snap.running_model):
                return self._better(corrected, self._model_verdict(t_s, snap, fresh), snap)
            return corrected
        return self._model_verdict(t_s, snap, fresh)

    def _better(self, corrected: Verdict, refitted: Verdict, snap: Snapshot) -> Verdict:
        """Of a correction and a refitted model, judged on the same rows since a change,
        the one that leaves less tracking error where the correction was checked (the
        newest rows, which it was not fitted to; the model was), if both pass and those
        rows ran the compensator both would replace; else the correction if it passes,
        the model if only it does.

        Which one is better depends on the loop and the change: on the simulated rig,
        1 s after +40 % payload, the correction left 13–19 % of the running one's error
        and the refit 17–25 %; on a 12 Hz loop behind 2 ms of delay the correction, a
        short FIR, left 33–46 % and the refit 9–19 %. The refit therefore waits for the
        first correction while the rows since the change are too few for one
        (:meth:`ChannelAdapter.ready`): judged alone 0.25 s earlier, the rig's first
        refits were loaded and left 2.3× its level before where the correction would
        have left 1.4×."""
        c, m = corrected.decision, refitted.decision
        if not m.accepted or m.design is None or snap.running is None:
            return corrected
        last_a, last_b, then = snap.spans[-1]
        if not c.accepted or then is not None:
            return refitted if not c.accepted else corrected
        cmp = compare_compensators(m.design, snap.running, snap.desired, snap.feedback,
                                   ((max(last_a, last_b - self._n_check - m.design.preview),
                                     last_b, None),), chunk=self._n_chunk)
        c.figures["refit_leaves"] = m.figures["refit_leaves"] = cmp.ratio
        m.figures["correction_leaves"] = float(c.figures["check_ratio"])
        if math.isfinite(cmp.ratio) and cmp.ratio < float(c.figures["check_ratio"]):
            return refitted
        return corrected

    def _model_verdict(self, t_s: float, snap: Snapshot, fresh: int) -> Verdict:
        u, y = snap.drive, snap.feedback
        if fresh and u.size - fresh < self.rows_to_refit(snap.running_model):
            return Verdict(Decision(t_s, False, f"{u.size - fresh} samples since the change "
                                    "of the loop: too few to refit its model yet",
                                    fault=False), None, "")
        try:
            model, chosen = self.model(snap.thetas, u, y)
            model, rows = self.refine(model, u, y, fresh, also=snap.running_model,
                                      prior=not snap.unanchored, then=snap.refitted)
            h1 = self._h1(model, u, y, fresh)
        except EhssError as exc:
            return Verdict(Decision(t_s, False, f"no model or H1 estimate: {exc}"), None, "")
        decision = self.compensator.assess(t_s, model, h1, snap.desired, window=(u, y),
                                           running=snap.current,
                                           residual_floor=snap.residual_floor,
                                           usual_disagreement=snap.disagreement)
        if rows:
            decision.figures["refit_rows"] = rows
        if fresh:
            decision.figures["fresh_rows"] = int(u.size - fresh)
        decision.figures["reference_rms"] = float(np.std(snap.desired))
        if decision.accepted and decision.design is not None and snap.current is not None \
                and snap.ran:
            decision = self._against_running(decision, snap)
        return Verdict(decision, model, chosen)

    def _quiet(self, snap: Snapshot) -> str:
        """Why the windows of ``snap`` cannot judge a model (empty if they can): a
        reference, over a third of the window, both 20 dB below its usual level (its
        RMS over the windows of the channel's recent loads, ``snap.reference_level``:
        the 20 dB within which the band is taken from its spectrum) and so quiet that
        even a model that leaves the channel's usual residual (``snap.residual_floor``)
        would fit the feedback by less than the guard's ``min_fit_pct``: its RMS below
        ``floor / (1 − min_fit_pct / 100)``.

        Between tests, or once a record has died away, the stream goes on with next to
        nothing in the band: the H1 estimate confirms no point, the estimator drifts
        where nothing excites it, and every judgement failed as a fault. On the
        simulated rig, a record stopped at 20 s for 10 s alarmed 1.4 s into the pause.
        Refused as no fault, such windows keep the last good compensator and raise no
        alarm. A failing sensor is judged as before: it does not quieten the reference.
        Both conditions: the first alone would skip a coda's last seconds, where a
        stuck sensor is still told by its residual (:meth:`AdaptiveCompensator.
        _judge_fit`); the second alone every judgement of a loop whose sensor noise is
        10 % of its feedback, where no model fits by 90 %.
        """
        floor, usual = snap.residual_floor, snap.reference_level
        if floor is None or usual is None or snap.desired.size < 3:
            return ""
        min_fit = self.compensator.guard.acceptance.min_fit_pct
        need = min(floor / (1.0 - min_fit / 100.0), QUIET_REFERENCE * usual)
        # in each third of the window (the H1 estimate's segments): a window that a
        # pause ended or began in is no more use than a quiet one
        level = min(float(np.std(part)) for part in np.array_split(snap.desired, 3))
        if level >= need:
            return ""
        return (f"the reference is quiet ({level:.3g} RMS over a third of the window, "
                f"below {need:.3g}: 20 dB under its usual {usual:.3g}, and too little for "
                f"a model leaving the usual residual to fit the feedback by {min_fit:g} "
                "%): nothing to judge")

    def _against_running(self, decision: Decision, snap: Snapshot) -> Decision:
        """A model's compensator replaces the running one only if, replayed on the
        rows of ``snap.ran``, it would not have left more tracking error (by more than
        ``load_sigmas`` standard errors of the ratio, if set)."""
        assert decision.design is not None and snap.current is not None
        cmp = compare_compensators(decision.design, snap.current, snap.desired,
                                   snap.feedback, snap.ran, chunk=self._n_chunk)
        figures = {**decision.figures, "against_running": cmp.ratio,
                   "against_running_se": cmp.standard_error}
        sigmas = self.settings.load_sigmas
        limit = 1.0 + sigmas * cmp.standard_error if sigmas else 1.0
        if cmp.ratio > limit:
            return Decision(decision.t_s, False, f"the model's compensator would leave "
                            f"{cmp.ratio:.2f} of the running one's tracking error "
                            f"(at most {limit:.2f})", figures=figures, fault=False)
        return Decision(decision.t_s, True, "", decision.design, figures)


def seen_alike(model: ehss.ArmaxModel, h1: FrequencyResponse, u: np.ndarray, fresh: int
               ) -> FrequencyResponse:
    """``h1`` (of the rows of ``u`` from ``fresh`` on) with each point's averaging
    taken out as far as ``model`` is concerned: times ``M(f) / Ĥ_M(f)``, ``Ĥ_M`` the
    same estimate of the model's own output on the same rows (simulated from rest over
    all of ``u``), so that the model's response at a point is compared with the
    loop's as the estimate saw both.

    A point averages the response over its bin, weighted by the window's main lobe and
    the drive's spectrum there: at the band's edges, where the drive's spectrum falls
    to nothing within a bin, and in short segments, that average is not the response
    at the bin's centre. On the 12 Hz loop behind 2 ms of delay 0.75 s after +40 % mass
    (segments of 0.26 s), the point at 19.5 Hz of a 0.5–20 Hz drive was 16.4° off the
    refitted model, and 0.3° off it seen alike: the estimate of the model's own output
    through the same segments shows the same bias, and the ratio of the two estimates
    compares like with like. An unstable model, or one whose estimate has no power at a
    point, is left as it is."""
    if not model.is_stable():
        return h1
    with np.errstate(over="ignore", invalid="ignore"):
        y_m = model.simulate(u)[fresh:]
    if not np.all(np.isfinite(y_m)) or not np.any(y_m):
        return h1
    h1_m = ehss.h1_estimate(u[fresh:], y_m, fs=h1.fs, nperseg=h1.nperseg,
                            delay=h1.delay_samples)
    ok = np.abs(h1_m.response) > 0
    response = h1.response.copy()
    response[ok] *= model.frequency_response(h1.freq_hz[ok]) / h1_m.response[ok]
    return dataclasses.replace(h1, response=response)


@dataclass(frozen=True)
class CompensationRecord:
    """What an :class:`AdaptiveLoop` run did.

    Attributes
    ----------
    fs : float
    channels : tuple of str
    desired, drive, feedback : ndarray, shape (n_channels, n)
    decisions : dict of str to list of dict
        Every judgement per channel (:meth:`Decision.to_dict`).
    loads : list of dict
        Compensators sent to the target: ``t_s``, ``channel``, ``apply_index``,
        ``crossfade``, ``accepted`` (by the target), ``model`` (``"estimator"`` or
        ``"tracker"``: whose model it inverts; ``"correction"``; ``"rollback"``: the
        compensator that ran before a load that raised the error, sent again, with
        that load's ``loaded_index`` and the rise, ``ratio``).
    events : list of dict
        Loads, refusals, alarms and clears, changes flagged and rollbacks.
    settings : dict
    """

    fs: float
    channels: tuple[str, ...]
    desired: np.ndarray = field(repr=False)
    drive: np.ndarray = field(repr=False)
    feedback: np.ndarray = field(repr=False)
    decisions: dict = field(repr=False)
    loads: list = field(repr=False)
    events: list = field(repr=False)
    settings: dict = field(repr=False)

    def tracking_rms(self, t0_s: float, t1_s: float) -> np.ndarray:
        """RMS of desired − feedback of each channel over ``[t0_s, t1_s)``."""
        a, b = int(round(t0_s * self.fs)), int(round(t1_s * self.fs))
        e = self.desired[:, a:b] - self.feedback[:, a:b]
        return np.sqrt(np.mean(e * e, axis=1))


class AdaptiveLoop:
    """Run a target block by block, adapting each channel's compensator.

    Parameters
    ----------
    target : Target
    settings : CompensationSettings
    loop : str, optional
    params : RigParams, optional
        The rig whose limits the drives must respect (with ``loop``).
    log : callable, optional
        Receives each event dict (loads, refusals that change, alarms, clears).
    """

    def __init__(self, target: Target, settings: CompensationSettings, *,
                 loop: str | None = None, params: Any = None,
                 log: Callable[[dict], None] | None = None) -> None:
        self.target = target
        self.fs = float(target.fs)
        scales, band = _scales_and_band(target, settings.band_hz, self.fs)
        self.band_hz = (float(band[0]), float(band[1]))
        settings = settings.for_band(self.band_hz).for_stream(len(target.channels), self.fs)
        self.settings = settings
        self.adapters = [
            ChannelAdapter(name, self.fs, self.band_hz, float(scales[k]) or 1.0, settings,
                           loop=loop, params=params, preview=target.preview)
            for k, name in enumerate(target.channels)]
        self._log = log
        self.events: list[dict] = []
        self.loads: list[dict] = []
        self._warm_up(loop, params)
        self._last_reason = [""] * len(self.adapters)
        # judgements on the worker: channel -> (sample to take it up at, t_s, future)
        self._pending: dict[int, tuple[int, float, Future]] = {}
        self._collect_after = 1
        # started here, like the warm-up, so that a target's stream does not wait for it
        self._worker: Executor | None = self._start_worker()

    def _warm_up(self, loop: str | None, params: Any) -> None:
        """One judgement on a throwaway channel, so that the estimator's compiled
        kernels are loaded before the first block: a target's stream does not wait."""
        n = int(self.settings.h1_window_for(self.band_hz) * self.fs)
        u = np.random.default_rng(0).standard_normal(n)
        warm = ChannelAdapter("warm-up", self.fs, self.band_hz, 1.0, self.settings,
                              loop=loop, params=params, preview=self.target.preview)
        warm.feed(u, 0.5 * u, u)
        self._warm_snapshot = warm.snapshot()
        warm.judge(0.0, self._warm_snapshot)

    def _event(self, record: dict) -> None:
        self.events.append(record)
        if self._log is not None:
            self._log(record)

    def _update(self, t_s: float, channels: list[int]) -> None:
        """Judge the channels whose turn it is: on the worker, to be taken up
        ``self._collect_after`` samples later, or here and now."""
        for k in channels:
            ad = self.adapters[k]
            # one compensator at a time: the last one sent must be in before the next
            if k in self._pending or not ad.compensator.due(t_s) \
                    or self.target.index < ad.busy_until or not ad.ready():
                continue
            snap = ad.snapshot()
            if self._worker is None:
                self._apply(k, t_s, ad.judge(t_s, snap))
                continue
            future = self._worker.submit(ad.judging, t_s, snap) \
                if isinstance(self._worker, ThreadPoolExecutor) \
                else self._worker.submit(_worker_judge, k, t_s, snap)
            self._pending[k] = (self.target.index + self._collect_after, t_s, future)

    def _collect(self, *, every: bool = False) -> None:
        """Take up the judgements whose time has come and apply them (``every``: all,
        recorded but not applied: the stream is over)."""
        for k, (due, t_s, future) in sorted(self._pending.items(), key=lambda kv: kv[1][0]):
            if every or self.target.index >= due:
                del self._pending[k]
                verdict = future.result()
                ad = self.adapters[k]
                if int(round(t_s * self.fs)) < ad.flagged_at and not every:
                    # judged on the loop before a change flagged since: an inverse of
                    # the loop that was, and a load that the first correction would
                    # have to wait for rows under (on the rig, +40 % payload, seeds
                    # 7, 8: sent, it left no correction to race the first refit)
                    self._event({"kind": "compensator_refused", "channel": ad.name,
                                 "t_s": t_s, "reason": "judged on the loop before the "
                                 f"change flagged at {ad.flagged_at / self.fs:.2f} s: "
                                 "not sent"})
                    continue
                ad.take(verdict)
                if not every:
                    self._apply(k, t_s, verdict.decision)

    def close(self) -> None:
        """Stop the worker (a worker process starts with the loop; :meth:`run` stops it
        at its end, and starts it anew if run again)."""
        if self._worker is not None:
            self._worker.shutdown()
            self._worker = None

    def _start_worker(self) -> Executor | None:
        where = self.settings.judge_in
        if where == "thread":
            return ThreadPoolExecutor(max_workers=1, thread_name_prefix="ehss-judge")
        if where == "stream":
            return None
        import multiprocessing

        pool = ProcessPoolExecutor(
            max_workers=1, mp_context=multiprocessing.get_context("spawn"),
            initializer=_worker_start,
            initargs=([ad.judging for ad in self.adapters], self._warm_snapshot))
        pool.submit(_worker_ready).result()      # started and warm before the stream
        return pool

    def _refused(self, k: int, t_s: float, d: Decision) -> None:
        ad = self.adapters[k]
        # the same refusal with other figures is logged once
        key = re.sub(r"[-+0-9.]+", "#", d.reason)
        if key != self._last_reason[k]:
            self._event({"kind": "compensator_refused", "channel": ad.name,
                         "t_s": t_s, "reason": d.reason})
        ad.refusals += d.fault  # a better compensator kept says nothing against the loop
        if d.fault and ad.compensator.current is not None and not ad.alarm \
                and ad.refusals >= self.settings.alarm_after:
            ad.alarm = True
            self._event({"kind": "alarm", "channel": ad.name, "t_s": t_s,
                         "text": f"compensator kept: {d.reason}"})
        self._last_reason[k] = key

    def _apply(self, k: int, t_s: float, d: Decision) -> None:
        """Log a refusal, or send an accepted design to the target."""
        ad = self.adapters[k]
        if not d.accepted or d.design is None:
            self._refused(k, t_s, d)
            return
        self._last_reason[k] = ""
        ad.refusals = 0
        if ad.alarm:
            ad.alarm = False
            self._event({"kind": "clear", "channel": ad.name, "t_s": t_s})
        design = d.design
        sent = self._send(k, t_s, design, not_before=ad.busy_until)
        if sent is None:
            return
        ad.started(sent["apply_index"] + sent["crossfade"], sent["apply_index"])
        load = {"kind": "compensator", "channel": ad.name, "t_s": t_s, **sent,
                "model": ad.chosen, "settle_samples": design.settle_samples, **d.figures,
                **design.errors()}
        self.loads.append(load)
        self._event(load)

    def _send(self, k: int, t_s: float, design: CompensatorDesign, *, not_before: int = 0
              ) -> dict | None:
        """Send a design to the target, to run in shadow for its settling time and
        cross-fade in (bumpless): its apply index, cross-fade and whether the target
        took it (None, logged, if the target cannot run it). A target's filter takes a
        load up once the cross-fade under way (to sample ``not_before``) is over,
        replacing one still in shadow, and runs it in shadow from there."""
        from ehss.target.filter import Compensator

        try:
            # the target's own checks (sizes, finite, every section stable)
            comp = Compensator(sos=design.sos, taps=design.taps, preview=design.preview,
                               fs_hz=design.fs_hz)
        except EhssError as exc:
            self._event({"kind": "compensator_refused", "channel": self.adapters[k].name,
                         "t_s": t_s, "reason": f"the target cannot run it: {exc}"})
            return None
        now = self.target.index + _ahead(self.target)
        fading = self.adapters[k].busy_from <= now < not_before
        apply_index = (not_before if fading else now) + design.settle_samples
        crossfade = max(1, int(round(self.settings.guard.crossfade_s * self.fs)))
        ok = self.target.load(k, comp, apply_index, crossfade)
        return {"apply_index": int(apply_index), "crossfade": crossfade, "accepted": bool(ok)}

    def _roll_back(self, k: int) -> None:
        """Undo the load the trigger dated a rise of the error to: send the compensator
        that ran before it again, as any load is sent; not a change of the loop (no
        following, no correction) and no refusal (no alarm)."""
        ad = self.adapters[k]
        load = ad.undo
        assert load is not None
        t_s = self.target.index / self.fs
        sent = self._send(k, t_s, load.design, not_before=ad.busy_until)
        if sent is None:
            ad.undo = None
            return
        ad.rolled_back(sent["apply_index"], sent["apply_index"] + sent["crossfade"])
        rise = 1.0 if ad.trigger is None else ad.trigger.rise
        event = {"kind": "compensator_rollback", "channel": ad.name, "t_s": t_s, **sent,
                 "model": "rollback", "loaded_index": load.apply_index, "ratio": rise,
                 "text": f"the compensator loaded at {load.apply_index / self.fs:.2f} s "
                         f"raised the error {rise:.1f}×: the one before it is sent again"}
        self.loads.append(event)
        self._event(event)

    def run(self, *, block_s: float = 0.05, duration_s: float | None = None,
            speed: float = math.inf, stop: Any = None) -> CompensationRecord:
        """Run until the target finishes, ``duration_s`` of stream time passes or
        ``stop`` (a :class:`threading.Event`) is set; ``speed`` × real time (inf: as
        fast as it computes)."""
        s = self.settings
        n_block = max(1, int(round(block_s * self.fs)))
        limit = math.inf if duration_s is None else int(round(duration_s * self.fs))
        # the channels take their turns spread over the update period, so that their
        # judgements (a design each, milliseconds) do not all fall in one block
        n_ch = max(1, len(self.adapters))
        spacing_s = s.update_s / n_ch
        first = max(s.start_s, s.update_s)
        next_update = [first + k * spacing_s for k in range(n_ch)]
        self._collect_after = max(1, int(round(spacing_s * self.fs)))
        if self._worker is None:
            self._worker = self._start_worker()
        parts: list[Any] = []
        try:
            self._stream(parts, n_block, limit, speed, stop, next_update)
        finally:
            if self._worker is not None:
                self._collect(every=True)
            self.close()
        cat = {name: np.concatenate([getattr(p, name) for p in parts], axis=1)
               for name in ("desired", "drive", "feedback")}
        return CompensationRecord(
            fs=self.fs, channels=tuple(self.target.channels), **cat,
            decisions={ad.name: [d.to_dict() for d in ad.compensator.log]
                       for ad in self.adapters},
            loads=list(self.loads), events=list(self.events),
            settings={**s.to_dict(), "band_hz": list(self.band_hz)})

    def _stream(self, parts: list, n_block: int, limit: float, speed: float, stop: Any,
                next_update: list[float]) -> None:
        """Step the target block by block, feeding the channels and judging in turn."""
        s = self.settings
        wall0 = time.monotonic()
        while not self.target.finished and self.target.index < limit:
            if stop is not None and stop.is_set():
                break
            ahead = self.target.index / self.fs / speed - (time.monotonic() - wall0)
            if ahead > 0:
                time.sleep(ahead)
            block = self.target.step(int(min(n_block, limit - self.target.index)))
            if not block.drive.shape[1]:
                continue
            parts.append(block)
            for k, ad in enumerate(self.adapters):
                if ad.feed(block.drive[k], block.feedback[k], block.desired[k]):
                    self._event({"kind": "compensator_change", "channel": ad.name,
                                 "t_s": self.target.index / self.fs,
                                 "at_load": ad.change_at_load})
                if ad.undo is not None:
                    self._roll_back(k)
            self._collect()
            t_s = self.target.index / self.fs
            turn = [k for k in range(len(next_update)) if t_s + 1e-12 >= next_update[k]]
            if turn and t_s <= s.adapt_until_s:
                self._update(t_s, turn)
            for k in turn:
                next_update[k] += s.update_s


def _start_up(model: ehss.ArmaxModel) -> int:
    """Samples after which ``model``, run from rest, has forgotten its start: its
    input's taps, and its slowest pole's decay (:func:`ehss._settle.decay_samples`)."""
    radius = float(np.max(np.abs(model.poles()), initial=0.0))
    return max(model.delay + model.b.size, decay_samples(radius))


def _scales_and_band(target: Target, band: tuple[float, float] | None, fs: float
                     ) -> tuple[np.ndarray, tuple[float, float]]:
    """Each channel's reference RMS, and the band (default: the first channel's
    reference band, from the target's whole desired reference)."""
    desired = getattr(target, "desired", None)
    if desired is None:
        # a remote target: its reference is not here ahead of time
        rms = getattr(target, "reference_rms", None)
        if rms is None:
            raise ParameterError("the target gives neither its desired reference nor each "
                                 "channel's reference_rms")
        scales = np.asarray(rms, dtype=float)
        if band is None:
            raise ParameterError("a remote target needs the band of its reference "
                                 "(band_hz / --band)")
        return scales, band
    desired = np.atleast_2d(desired)
    scales = np.sqrt(np.mean(desired**2, axis=1))
    if band is None:
        lo, hi = reference_band(desired[0], fs)
        band = (max(lo, 2.0 * fs / desired.shape[1]), hi)
    return scales, band


# the worker process's copies of the channels' judging
_WORKER_JUDGING: list[Judging] = []


def _worker_start(judging: list[Judging], warm: Snapshot) -> None:
    _WORKER_JUDGING[:] = judging
    judging[0](0.0, warm)            # the compiled kernels loaded before the stream


def _worker_ready() -> bool:
    return True


def _worker_judge(k: int, t_s: float, snap: Snapshot) -> Verdict:
    return _WORKER_JUDGING[k](t_s, snap)


# ----------------------------------------------------------------------------- over UDP
class DatagramSender:
    """Sends compensators to a remote target, one :mod:`ehss.target.datagram` each.

    Parameters
    ----------
    address : (host, port)
        The target's compensator port.
    first_sequence : int, optional
        Sequence number of the first datagram (default: the Unix time in ms, so that a
        restarted host keeps numbering upwards).
    """

    def __init__(self, address: tuple[str, int], *, first_sequence: int | None = None) -> None:
        import socket

        self.address = (str(address[0]), int(address[1]))
        self.sequence = int(time.time() * 1000) if first_sequence is None \
            else int(first_sequence)
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sent = 0

    def send(self, channel: int, compensator: Any, apply_index: int, crossfade: int) -> bool:
        """Encode and send one update; True once sent (the target may still refuse it)."""
        from ehss.target.datagram import CompensatorUpdate, encode

        update = CompensatorUpdate(channel=channel, sequence=self.sequence,
                                   apply_index=int(apply_index), crossfade=int(crossfade),
                                   compensator=compensator)
        self._sock.sendto(encode(update), self.address)
        self.sequence += 1
        self.sent += 1
        return True

    def close(self) -> None:
        self._sock.close()


@dataclass(frozen=True)
class _UdpBlock:
    first_index: int
    desired: np.ndarray
    drive: np.ndarray
    feedback: np.ndarray


class UdpTarget:
    """A remote target as :class:`AdaptiveLoop` drives it.

    The target streams, in the ``ehss live`` wire format, each channel's drive
    (``ref<k>``, the model's input), feedback (``fb<k>``) and desired reference
    (``des<k>``), and takes compensators back as :mod:`ehss.target.datagram` datagrams;
    its filters read the reference ``preview`` samples ahead, and sample indices are the
    stream's.

    Parameters
    ----------
    source : UdpSource
        Receives the stream (its layout must have ``des<k>`` for every channel).
    sender : DatagramSender
    fs : float
    preview : int
    reference_rms : sequence of float
        RMS of each channel's desired reference (the estimators' scale).
    idle_stop_s : float
        The run ends when no data came for this long after the first.
    """

    def __init__(self, source: Any, sender: DatagramSender, *, fs: float, preview: int,
                 reference_rms: Any, idle_stop_s: float = 1.0) -> None:
        layout = source.layout
        self.channels = tuple(layout.channels)
        missing = [f"des{c}" for c in self.channels if f"des{c}" not in layout.fields]
        if missing:
            raise ParameterError(f"the stream has no field {missing[0]!r}: a target that "
                                 "takes compensators sends each channel's desired reference")
        self.source, self.sender = source, sender
        self.fs, self.preview = float(fs), int(preview)
        self.reference_rms = np.asarray(reference_rms, dtype=float)
        self._ri, self._fi = layout.ref_index, layout.fb_index
        self._di = [layout.fields.index(f"des{c}") for c in self.channels]
        self._idle = float(idle_stop_s)
        self._last: float | None = None
        self._done = False
        self.index = 0
        # (end index, arrival time) of the first and the latest block: the target's clock
        self._first_arrival: tuple[int, float] | None = None
        self._latest_arrival: tuple[int, float] | None = None
        self._largest_block = 0

    @property
    def finished(self) -> bool:
        return self._done or self.source.finished

    def load(self, channel: int, compensator: Any, apply_index: int, crossfade: int) -> bool:
        return self.sender.send(channel, compensator, apply_index, crossfade)

    def _arrived(self, first: int, n: int, arrival: float) -> None:
        self._latest_arrival = (first + n, arrival)
        if self._first_arrival is None:
            self._first_arrival = (first + n, arrival)
        self._largest_block = max(self._largest_block, n)

    def ahead(self) -> int:
        """Samples the target is estimated to be past :attr:`index` now.

        The target sent the latest block that arrived when it had computed it, and has
        gone on at its own rate since: the samples that arrived but are not yet taken,
        those it has computed since that block's arrival (the rate measured from the
        arrival times of the stream so far, ``fs`` until a second has come), and one
        more block, the most it can be ahead of what it has sent."""
        if self._latest_arrival is None or self._first_arrival is None:
            return 0
        (end0, t0), (end, t) = self._first_arrival, self._latest_arrival
        rate = (end - end0) / (t - t0) if t - t0 >= 1.0 else self.fs
        since = max(0.0, time.time() - t) * rate
        return max(0, end - self.index) + int(math.ceil(since)) + self._largest_block

    def step(self, n: int) -> _UdpBlock:
        """The samples that arrived (at least one unless the stream went idle)."""
        got: list[np.ndarray] = []
        have = 0
        while have < n:
            blocks = self.source.poll(0.05)
            for b in blocks:
                got.append(b.samples)
                have += b.samples.shape[0]
                self._arrived(b.first_index, b.samples.shape[0], b.arrival_s)
            now = time.monotonic()
            if blocks:
                self._last = now
            elif self._last is not None and now - self._last >= self._idle:
                self._done = True
                break
            elif have:
                break
        x = np.concatenate(got) if got else np.empty((0, len(self.source.layout.fields)))
        first = self.index
        self.index += x.shape[0]
        return _UdpBlock(first, x[:, self._di].T.copy(), x[:, list(self._ri)].T.copy(),
                         x[:, list(self._fi)].T.copy())
