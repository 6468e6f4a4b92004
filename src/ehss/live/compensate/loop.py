"""The loop that runs a target block by block and adapts each channel's compensator
(:class:`AdaptiveLoop`), the record of its run (:class:`CompensationRecord`), and the
functions its worker process runs.
"""

from __future__ import annotations

import math
import re
import time
from collections.abc import Callable
from concurrent.futures import Executor, Future, ProcessPoolExecutor, ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ehss.compensation.adaptive import Decision
from ehss.compensation.compensator_design import CompensatorDesign, pass_through
from ehss.errors import EhssError, ParameterError
from ehss.live.channel import reference_band
from ehss.live.compensate.adapter import ChannelAdapter
from ehss.live.compensate.judging import Judging, Snapshot, Verdict
from ehss.live.compensate.settings import CompensationSettings, Target, _ahead


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
        settings = settings.for_band(self.band_hz).for_stream(
            len(target.channels), self.fs, target.preview if settings.mode == "preview" else 0)
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
            fault = ad.running_fault()
            if fault:
                self._switch_off(k, t_s, fault)
                continue
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
                "model": ad.chosen, "taps": int(design.taps.size),
                "settle_samples": design.settle_samples, **d.figures,
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

    def _switch_off(self, k: int, t_s: float, reason: str) -> None:
        """Send the reference as it is (:func:`~ehss.compensation.compensator_design.
        pass_through`), as any load is sent, and raise an alarm: the drive of the
        compensator that ran failed the checks, which a drive equal to the reference
        passes (:meth:`AdaptiveCompensator.drive_fault`). A compensator whose drive
        passes is loaded again as before."""
        ad = self.adapters[k]
        comp = ad.compensator
        off = pass_through(self.fs, comp.band_hz, mode=comp.mode, preview=comp.preview,
                           n_taps=comp.n_taps)
        sent = self._send(k, t_s, off, not_before=ad.busy_until)
        if sent is None:
            return
        ad.switched_off(off, sent["apply_index"], sent["apply_index"] + sent["crossfade"])
        event = {"kind": "compensator_off", "channel": ad.name, "t_s": t_s, **sent,
                 "model": "off", "reason": reason,
                 "text": f"the drive of the compensator that ran failed the checks "
                         f"({reason}): the reference is sent as it is"}
        self.loads.append(event)
        self._event(event)
        if not ad.alarm:
            ad.alarm = True
            self._event({"kind": "alarm", "channel": ad.name, "t_s": t_s,
                         "text": f"compensation off: {reason}"})

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
                rises = ad.level_rises
                if ad.feed(block.drive[k], block.feedback[k], block.desired[k]):
                    self._event({"kind": "compensator_change", "channel": ad.name,
                                 "t_s": self.target.index / self.fs,
                                 "at_load": ad.change_at_load})
                if ad.level_rises > rises:
                    self._event({"kind": "compensator_level", "channel": ad.name,
                                 "t_s": self.target.index / self.fs,
                                 "text": "the error rose with the reference's level (a new "
                                         "test level): the change trigger learns it anew"})
                if ad.undo is not None:
                    self._roll_back(k)
            self._collect()
            t_s = self.target.index / self.fs
            turn = [k for k in range(len(next_update)) if t_s + 1e-12 >= next_update[k]]
            if turn and t_s <= s.adapt_until_s:
                self._update(t_s, turn)
            for k in turn:
                next_update[k] += s.update_s


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
