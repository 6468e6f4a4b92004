"""Settings of adaptive compensation (:class:`CompensationSettings`, and the constants
its defaults come from) and what it drives (:class:`Target`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, Protocol

from ehss._checks import check_int, check_real
from ehss.compensation.adaptive import UpdateGuard
from ehss.compensation.compensator_design import MODES, fir_taps
from ehss.errors import ParameterError
from ehss.live.detect import TriggerSettings
from ehss.target.filter import MAX_TAPS

#: The H1 window's length where the band is wide enough (s), and how many of the
#: estimate's points a narrower band must hold in it
#: (:meth:`CompensationSettings.h1_window_for`): its segments are a third of the window,
#: and the narrowband test needs more than 8 (:mod:`ehss.compensation.adaptive`).
H1_WINDOW_S = 1.5
H1_BAND_POINTS = 8
#: Channels × sample rate (samples a second) up to which :class:`AdaptiveLoop` refits
#: the models by default (``CompensationSettings.refine`` None). A refit's cost grows
#: with the rows of its window: with the refit from the data alone, 10–11 ms at 1 kHz,
#: 26–32 ms at 5 kHz on the machine of BENCHMARKS.md (4–7 and 8–13 ms without it), and
#: a judgement that refits takes 1.2–1.7× what it took, every ``update_s`` per channel.
#: Up to 10 000 channel-samples a second (2 channels at 5 kHz, 5 at 2 kHz) that leaves
#: the worker most of a core, as 16 000 did before that refit; 8 channels at 5 kHz
#: would need more than one.
REFINE_LOAD = 10_000.0

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
        simulated rig closer to the level before (docs/adaptive_compensation.md):
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
        (:func:`ehss.compensation.correction.fit_correction`) as soon as they suffice,
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
        left (:func:`ehss.compensation.correction.compare_compensators`; 2, one-sided,
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
        The target's filter sizes (at most :data:`ehss.target.filter.MAX_TAPS`, ...).
        ``n_taps`` None: :func:`~ehss.compensation.compensator_design.fir_taps` of the
        stream's rate and the target's preview, at most the target's capacity
        (:meth:`for_stream`): 0.256 s of samples, 256 at 1 kHz, 1280 at 5 kHz.
    guard : UpdateGuard
    refine : bool or None
        Whether each model judged is first refitted to the output errors of the
        windows (:meth:`Judging.refine`): the output error of a model on the drive is
        the tracking error its inverse will leave, which the recursive estimator does
        not minimise. On the simulated rig it lowered the steady tracking error by
        11–13 % (18–31 % at the heavier payload), and on the 25 Hz servo it brought the
        error back to its level 2 s after +40 % mass (1.0–1.1× over [22, 24) s against
        1.7–3.1×; docs/adaptive_compensation.md); on a 15 Hz loop with a 40 Hz
        oil-column mode at the band's top, its refit from the data alone cut the error
        from 1/13 of the uncompensated to 1/120. It takes 10–32 ms a judgement (1 to
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
    n_taps: int | None = None
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
        if self.n_taps is not None:
            check_int(self.n_taps, "n_taps", lo=1, hi=MAX_TAPS)
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

    def for_stream(self, n_channels: int, fs: float, preview: int = 0
                   ) -> CompensationSettings:
        """These settings for a stream of ``n_channels`` at ``fs`` whose target reads
        ``preview`` samples ahead: ``refine`` None becomes whether channels × fs ≤
        :data:`REFINE_LOAD` (what the worker's share of a core allows), counted in
        windows of :data:`H1_WINDOW_S`: a refit's cost grows with its rows, and a longer
        window (``h1_window_s``, :meth:`for_band`) has more; ``n_taps`` None becomes
        :func:`~ehss.compensation.compensator_design.fir_taps` of ``fs`` and
        ``preview``."""
        out = self
        if out.n_taps is None:
            out = dataclasses.replace(out, n_taps=fir_taps(fs, preview, most=MAX_TAPS))
        if out.refine is None:
            window = H1_WINDOW_S if out.h1_window_s is None else out.h1_window_s
            out = dataclasses.replace(
                out, refine=n_channels * fs * window / H1_WINDOW_S <= REFINE_LOAD)
        return out

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
