"""One channel of adaptive compensation (:class:`ChannelAdapter`): its estimators, sliding
windows and compensator, and what it does when its loop changes.
"""

from __future__ import annotations

import collections
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

import ehss
from ehss.compensation.adaptive import AdaptiveCompensator, Decision
from ehss.compensation.compensator_design import CompensatorDesign
from ehss.live.compensate.judging import QUIET_REFERENCE, Judging, Snapshot, Verdict
from ehss.live.compensate.settings import CompensationSettings
from ehss.live.detect import ONSET_Z, BaselineResidual, TrackingTrigger, block_statistic

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
        # models refused in a row for missing the H1 estimate at the band's lowest
        # point (at least ``alarm_after`` of them: judged over the band above it)
        self._low_edge = 0
        self._top_edge = 0      # the same at its highest point (judged below it)
        # validated models refused in a row for a drive beyond the gain checks or the
        # rig's limits (at least ``alarm_after`` of them: narrowed to where it passes)
        self._over = 0
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
        # a change is followed and no compensator has been sent since: the first one
        # sets the trigger on again (TrackingTrigger.test_on)
        self._test_on_due = False
        # the reference as it is, sent when compensation was switched off (None: never)
        self._off: CompensatorDesign | None = None

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
        changed = self.trigger is not None and self.trigger(desired - feedback, desired)
        if changed:
            self._began = None
            self.undo = self._load_that_rose()
            changed = self.undo is None
        if changed:
            self.follow_change(None if self._began is None
                               else (self._n - self._began) / self.fs)
        return changed

    @property
    def level_rises(self) -> int:
        """Rises of the error the trigger took for a new test level, not a change
        (:attr:`~ehss.live.detect.TrackingTrigger.level_rises`)."""
        return 0 if self.trigger is None else self.trigger.level_rises

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
        self._test_on_due = True
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
        elif self.trigger is not None and self._test_on_due:
            # after a change flagged, the first compensator that follows it: the
            # trigger tests on from the level it leaves
            self.trigger.test_on(until - self._n)
        self._test_on_due = False
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
        self._test_on_due = False
        self.compensator.current = load.design
        self.compensator.current_model = load.model
        self.busy_from, self.busy_until = apply_index, until
        self._ran.append((until, load.design))
        self._running, self._running_model, self._before = load.design, load.model, None
        if self.trigger is not None:
            self.trigger.rearm(until - self._n)

    def running_fault(self) -> str:
        """Why the drive the target ran since the compensator that runs took over
        fails the checks a new compensator's drive must pass, on the same reference
        (:meth:`AdaptiveCompensator.drive_fault`), or empty; also while none runs but
        the reference as it is, or it has run alone for less than the guard's fresh
        stretch (``fit_s``). Its gains against the reference count only where the
        reference holds at least :data:`~ehss.live.compensate.judging.QUIET_REFERENCE`
        of its usual RMS (over the windows of the channel's recent loads): as a record
        fades out, the compensator's own memory outlasts it and the ratio grows without
        bound (a pause on the rig switched compensation off, "inf×"); the rig's limits
        count always.

        The guard judges each new compensator on the recent reference; the one that
        runs meets every reference after it. In causal mode its gain above the band
        (about 90 on the rig's position loop) is harmless for a band-limited
        reference, but 3 % of broadband noise added to the reference took the drive
        to 0.8–0.9 m/s against the rig's 0.2 m/s for as long as it lasted, while every
        new compensator was refused for it."""
        comp = self.compensator
        n_check = max(1, int(round(self.settings.guard.fit_s * self.fs)))
        a = self.busy_until - (self._n - self.window.fill)
        if comp.current is None or comp.current is self._off or self.busy_until > self._n \
                or self.window.fill - max(0, a) < n_check:
            return ""
        u, _, r = self.window.latest()
        u, r = u[max(0, a):], r[max(0, a):]
        gains = len(self._levels) >= RESIDUAL_LOADS[0] \
            and float(np.std(r)) >= QUIET_REFERENCE * float(np.median(self._levels))
        return comp.drive_fault(u, r, gains=gains)

    def switched_off(self, design: CompensatorDesign, apply_index: int, until: int) -> None:
        """Compensation is off: ``design`` (the reference passed as it is,
        :func:`~ehss.compensation.compensator_design.pass_through`) is sent and fades in
        from sample ``apply_index`` to ``until``. It runs with no model, nothing before
        it may be undone or corrected any more, and the trigger learns the error
        anew from ``until`` (many times the compensated one: not a change)."""
        self.undo = None
        self._undoable = []
        self._test_on_due = False
        self._correct_until = 0
        self._spans = []
        self._off = design
        self.compensator.current = design
        self.compensator.current_model = None
        self.busy_from, self.busy_until = apply_index, until
        self._ran.append((until, design))
        self._running, self._running_model, self._before = design, None, None
        if self.trigger is not None:
            self.trigger.restart(until - self._n)

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
        # a band that reaches past what the loop follows (its drives keep failing the
        # checks) ends where the models miss first: only then are they judged below
        # its top (a band merely over a resonance that the reference hardly excites
        # is not: the specimen under a rolled-off reference, judged below a top of
        # 64.5 Hz, loaded such models early and tracked 7x better than none, not 21x)
        over = self._over >= self.settings.alarm_after
        return Snapshot(u, y, r, np.mean([t for _, t in self._thetas], axis=0),
                        self._base if spans else None, spans, self.compensator.current,
                        self._ran_spans(), fresh, self.compensator.current_model,
                        unanchored, self._refitted if unanchored else None, floor, level,
                        usual, self._low_edge >= self.settings.alarm_after,
                        self._top_edge >= self.settings.alarm_after and over,
                        over, self._top_edge >= self.settings.alarm_after)

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
        self._low_edge = _at_edge(self._low_edge, verdict.decision, self.settings.alarm_after)
        self._top_edge = _at_edge(self._top_edge, verdict.decision, self.settings.alarm_after,
                                  top=True)
        self._over = _over(self._over, verdict.decision, self.settings.alarm_after)
        # (a refusal whose miss the estimate's averaging explains, Judging.
        # _bias_explained, tells how the estimate is biased, not how the models scatter)
        if "h1_phase_deg" in figures and "h1_seen_phase_deg" not in figures \
                and not (verdict.decision.fault and not verdict.decision.accepted):
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


def _at_edge(count: int, decision: Decision, then: int, *, top: bool = False) -> int:
    """The models refused in a row for missing the H1 estimate furthest at the band's
    lowest point (``top``: its highest), after ``decision``: one more for such a
    refusal, none after a model validated over the whole band; a model accepted over
    the band above that point (``validated_from_hz``; below it, ``validated_to_hz``),
    or refused for another reason, leaves the count as it is.

    Held there ``then`` times in a row (``alarm_after``, 3), a channel's models miss
    the loop at that point, not by scatter: a healthy rig's models are refused by 4 %
    of its judgements (6 of 159, :data:`~ehss.compensation.adaptive.NEAR_MISS`), three
    in a row by chance at most once in 0.04⁻³ ≈ 16 000 judgements (3.3 h of a channel
    judged every 0.75 s) even if every refusal fell at that point, against 53 of 61
    refusals at 4.88 Hz on the acceleration loop at 5 kHz."""
    f = decision.figures
    # at the top, a model accepted against the estimate seen alike (``top_biased``,
    # which the count enables) keeps it as well
    edge, kept = ("h1_highest_hz", ("validated_to_hz", "h1_seen_alike")) if top else \
        ("h1_lowest_hz", ("validated_from_hz",))
    return _in_a_row(count, decision, then, kept,
                     "h1_worst_hz" in f and f["h1_worst_hz"] == f.get(edge))


def _over(count: int, decision: Decision, then: int) -> int:
    """The validated models refused in a row for a drive beyond the gain checks or the
    rig's limits (``drive_refused``), after ``decision``: one more for such a refusal,
    none after a model accepted over the whole band; a model accepted over a narrower
    band (``narrowed_to_hz``), or refused for another reason, leaves the count as it is.

    Held there ``then`` times in a row (``alarm_after``, 3), the band reaches past what
    the loop can follow within the rig's bounds, and a model's inverse is loaded up to
    where its drive passes (:meth:`~ehss.compensation.adaptive.AdaptiveCompensator.
    assess`, ``narrow_top``). A single refusal keeps the last good inverse over the
    whole band: the rig's position loop under its default reference asks a peak
    velocity just past its limit once in minutes (README)."""
    return _in_a_row(count, decision, then, ("narrowed_to_hz",),
                     bool(decision.figures.get("drive_refused")))


def _in_a_row(count: int, decision: Decision, then: int, kept_by: tuple[str, ...],
              counts: bool) -> int:
    """A count of refusals in a row, capped at ``then``, after ``decision``: one more
    for a refusal that ``counts``; kept by a model accepted with one of the figures
    ``kept_by`` (accepted under a rule the count enables), reset by any other
    accepted; a refusal for another reason leaves it as it is."""
    if decision.accepted:
        return count if any(k in decision.figures for k in kept_by) else 0
    return min(count + 1, then) if counts else count


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
