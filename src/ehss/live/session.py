"""A live session: samples from a source through the channels' estimators and change
detection into the recording, with snapshots for a display.

The session composes parts with one job each (:mod:`ehss.live.meters`): the lag and
rate meters, the sliding H1 estimates, the scheduler of evaluations and their history,
and the recorder (:class:`~ehss.live.recording.LiveRecorder`). The loop never waits on a
display: a :class:`~ehss.live.snapshot.SessionSnapshot` is handed to ``publish`` (which
must not block; the dashboard's queue drops a snapshot it cannot take, never samples),
and the recording is flushed at most every ``flush_s``. The source's own buffer (the
socket's receive buffer for UDP, 8 MiB) absorbs the time a flush or a snapshot takes.

:meth:`LiveSession.run` polls the source until it ends; a caller that paces the stream
itself (the adaptive compensation, which steps the rig) calls :meth:`LiveSession.step`
after each block it hands the source, and :meth:`LiveSession.close` at the end.
"""

from __future__ import annotations

import collections
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

import ehss
from ehss._warm import warm_up
from ehss.errors import ParameterError
from ehss.live.channel import ChannelProcessor, EstimatorSettings, RefitTurns
from ehss.live.detect import BaselineResidual, DetectionSettings
from ehss.live.meters import (
    Evaluation,
    EvaluationHistory,
    EvaluationScheduler,
    LagMeter,
    RateMeter,
    SlidingH1,
)
from ehss.live.recording import LiveRecorder, check_new_recording
from ehss.live.snapshot import (
    ChannelSnapshot,
    CompensationSnapshot,
    LagStats,
    SessionSnapshot,
)
from ehss.live.source import Block, Source

__all__ = ["LiveReport", "LiveSession"]

#: Kinds of event the displays list (the latest 50).
_SHOWN = ("alarm", "clear", "message", "compensator", "compensator_refused",
          "compensator_alarm", "compensator_clear", "compensator_change",
          "compensator_level", "compensator_rollback")


@dataclass(frozen=True)
class LiveReport:
    """What a session did.

    Attributes
    ----------
    samples : int
        Samples processed per channel.
    stream_s : float
        Stream time processed, s.
    wall_s, cpu_s : float
        Wall-clock time and CPU time of this process, s.
    counters : dict
        The source's counters (see :data:`ehss.live.source.COUNTERS`).
    lag_ms : LagStats
        The estimator's lag behind the newest packet (from its arrival to the end of its
        processing), ms.
    alarms : list of dict
        Alarm and clear events.
    final_theta : dict
        θ̂ of each channel at the end.
    active_wall_s, active_cpu_s : float
        Wall-clock and CPU time from the first block of data to the last (the CPU share
        of the processing is their ratio).
    setup_ms : float
        Lag of the first poll, which also built the channels and opened the recording.
    settings : dict
        The estimator's and the detection's settings, and the forgetting factor.
    detection_started : dict of str to bool
        Whether each channel's change detection started (else no alarm could come);
        one learning its loop anew at the end (``compare="recent"``) did start.
    """

    samples: int
    stream_s: float
    wall_s: float
    cpu_s: float
    counters: dict
    lag_ms: LagStats
    alarms: list
    final_theta: dict = field(repr=False)
    active_wall_s: float = math.nan
    active_cpu_s: float = math.nan
    setup_ms: float = math.nan
    settings: dict = field(default_factory=dict, repr=False)
    detection_started: dict = field(default_factory=dict)

    @property
    def cpu_share(self) -> float:
        """CPU time over wall-clock time while data came."""
        return self.active_cpu_s / self.active_wall_s if self.active_wall_s > 0 else math.nan

    def to_dict(self) -> dict[str, Any]:
        """The JSON report of ``ehss live --report`` (without ``versions``)."""
        return {
            "samples": self.samples, "stream_s": self.stream_s, "wall_s": self.wall_s,
            "cpu_s": self.cpu_s, "active_wall_s": self.active_wall_s,
            "active_cpu_s": self.active_cpu_s, "cpu_share": self.cpu_share,
            "counters": dict(self.counters), "lag_ms": self.lag_ms.to_dict(),
            "setup_ms": self.setup_ms, "settings": self.settings,
            "alarms": list(self.alarms),
            "final_theta": {k: (None if v is None else np.asarray(v).tolist())
                            for k, v in self.final_theta.items()},
            "detection_started": dict(self.detection_started),
        }


class _Publisher:
    """Where snapshots go, how often, and what they carry besides the channels: the rate
    meter, the sliding H1 estimates (for the dashboard), the compensation's state."""

    def __init__(self, publish: Callable[[SessionSnapshot], None] | None, every_s: float,
                 h1: SlidingH1 | None,
                 compensation: Callable[[], CompensationSnapshot] | None) -> None:
        self._publish = publish
        self._every_s = float(every_s)
        self._last = -math.inf
        self.rate = RateMeter()
        self.h1 = h1
        self.compensation = compensation

    def due(self) -> bool:
        """Whether a snapshot is due (``every_s`` of wall time after the last)."""
        return self._publish is not None and \
            time.monotonic() - self._last >= self._every_s

    def publish(self, snap: SessionSnapshot) -> None:
        self._last = time.monotonic()
        if self._publish is not None:
            self._publish(snap)


class _Clock:
    """Wall-clock and CPU time of the whole run and of the span that had data."""

    def __init__(self) -> None:
        self.start = (time.monotonic(), time.process_time())
        self.first: tuple[float, float] | None = None
        self.last: tuple[float, float] | None = None
        self.last_data: float | None = None

    def data(self) -> None:
        now = (time.monotonic(), time.process_time())
        if self.first is None:
            self.first = now
        self.last = now
        self.last_data = now[0]

    def active(self) -> tuple[float, float]:
        if self.first is None or self.last is None:
            return math.nan, math.nan
        return self.last[0] - self.first[0], self.last[1] - self.first[1]


class LiveSession:
    """Run a source through the channels.

    Parameters
    ----------
    source : Source
    est : EstimatorSettings
    det : DetectionSettings
    baselines : dict of str to ArmaxModel, optional
        Baseline model per channel name (a channel without one learns its own).
    record : str or Path, optional
        HDF5 file to record to (must not exist).
    update_s : float
        Evaluation period (stream time), s.
    publish : callable, optional
        Receives a :class:`SessionSnapshot` every ``display_s`` of wall time; must not
        block.
    display_s : float
    h1 : bool
        Compute the sliding H1 estimates for the snapshots (for the dashboard).
    settings : dict, optional
        Extra JSON-able settings to store with the recording.
    log : callable, optional
        Receives each event dict as it happens (e.g. to print alarms).
    batch_s : float
        After the first block of a poll, wait up to this long for more before processing
        (the estimators' cost is mostly per call): the lag behind the newest datagram is
        unchanged, an older one waits at most this much longer.
    compensation : callable, optional
        Returns the state of adaptive compensation running beside the channels, for the
        snapshots.
    """

    def __init__(
        self, source: Source, *, est: EstimatorSettings, det: DetectionSettings,
        baselines: dict[str, ehss.ArmaxModel] | None = None, record: str | Path | None = None,
        update_s: float = 0.1, publish: Callable[[SessionSnapshot], None] | None = None,
        display_s: float = 0.5, h1: bool = False, settings: dict | None = None,
        log: Callable[[dict], None] | None = None, batch_s: float = 0.002,
        compensation: Callable[[], CompensationSnapshot] | None = None,
    ) -> None:
        if not (isinstance(update_s, (int, float)) and math.isfinite(update_s)
                and update_s > 0):
            raise ParameterError(f"update_s={update_s!r} must be finite and > 0 (s)")
        if not (isinstance(batch_s, (int, float)) and 0 <= batch_s < 1):
            raise ParameterError(f"batch_s={batch_s!r} must be in [0, 1) s")
        self.source = source
        self.layout = source.layout
        self.est, self.det = est, det
        self.baselines = dict(baselines or {})
        unknown = set(self.baselines) - set(self.layout.channels)
        if unknown:
            raise ParameterError(f"baselines for unknown channels {sorted(unknown)}; the "
                                 f"stream has {', '.join(self.layout.channels)}")
        self._record_path = None if record is None else check_new_recording(record)
        self._update_s = float(update_s)
        self._display = _Publisher(publish, display_s, SlidingH1() if h1 else None,
                                   compensation)
        self._batch_s = float(batch_s)
        self._settings = dict(settings or {})
        self._log = log
        self.fs: float | None = source.fs
        _warm_up(est)
        self.channels: list[ChannelProcessor] = []
        self.recorder: LiveRecorder | None = None
        self.events: list[dict] = []
        self._inbox: collections.deque[tuple[dict, float]] = collections.deque()
        self._held: list[Block] = []
        self._n = 0
        # the index of the sample after the last one processed (a jump: samples lost)
        self._next_index: int | None = None
        self._scheduler: EvaluationScheduler | None = None
        self._history = EvaluationHistory(est.n_params)
        self._lag = LagMeter()
        self._skip_lag = False
        self.setup_ms = math.nan
        self._clock: _Clock | None = None
        self._closed = False

    # ------------------------------------------------------------------ setup
    def _infer_fs(self) -> bool:
        ti = self.layout.time_index
        x = np.concatenate([b.samples for b in self._held])
        if ti is None:
            raise ParameterError("the sample rate is unknown: give --fs, or send a field 't'")
        if x.shape[0] < 3:
            return False
        step = float(np.median(np.diff(x[:, ti])))
        if not (math.isfinite(step) and step > 0):
            raise ParameterError("the 't' field does not increase: give --fs")
        self.fs = 1.0 / step
        return True

    def _setup(self, fs: float) -> None:
        self._scheduler = EvaluationScheduler(max(1, int(round(self._update_s * fs))), fs)
        turns = RefitTurns()          # the channels' refits share one thread
        self.channels = [
            ChannelProcessor(name, fs, self.est, self.det, self.baselines.get(name),
                             refit_turns=turns)
            for name in self.layout.channels
        ]
        if self._record_path is not None:
            self.recorder = LiveRecorder(self._record_path, self.layout, fs,
                                         self.est.n_params,
                                         {**self.settings(), "update_s": self._update_s,
                                          **self._settings})
        self._event({"kind": "start", "fs": fs, "channels": list(self.layout.channels),
                     "forgetting": self.est.lam(fs)})

    def settings(self) -> dict[str, Any]:
        """The estimator's and the detection's settings, and the forgetting factor."""
        return {"estimator": self.est.to_dict(), "detection": self.det.to_dict(),
                "forgetting": self.est.lam(self.fs) if self.fs else None}

    # ------------------------------------------------------------------ events
    @property
    def t_s(self) -> float:
        """Stream time processed, s."""
        return self._n / self.fs if self.fs else 0.0

    def add_event(self, record: dict, t_s: float | None = None) -> None:
        """Log, record and keep an event (a JSON-able dict with a ``kind``) at stream
        time ``t_s`` (default: now in the stream). Safe from any thread: the event is
        taken in by the session's next :meth:`step` (or :meth:`close`)."""
        self._inbox.append((record, self.t_s if t_s is None else t_s))

    def _take_events(self) -> None:
        while self._inbox:
            self._event(*self._inbox.popleft())

    def _event(self, record: dict, t_s: float | None = None) -> None:
        record = {"t_s": self.t_s if t_s is None else t_s, "wall": time.time(), **record}
        self.events.append(record)
        if self.recorder is not None:
            self.recorder.event(record)
        if self._log is not None:
            self._log(record)

    # ------------------------------------------------------------------ processing
    def _consume(self, x: np.ndarray, sched: EvaluationScheduler) -> None:
        cols = np.ascontiguousarray(x.T)
        ri, fi = self.layout.ref_index, self.layout.fb_index
        i, n = 0, x.shape[0]
        while i < n:
            take = min(n - i, sched.next_boundary - self._n)
            for k, proc in enumerate(self.channels):
                proc.feed(cols[ri[k], i:i + take], cols[fi[k], i:i + take])
            self._n += take
            i += take
            if self._n == sched.next_boundary:
                for ev in sched.capture(self._n, self.channels, self._event):
                    self._completed(ev)

    def _completed(self, ev: Evaluation) -> None:
        if self.recorder is not None:
            self.recorder.estimate(ev.t, ev.theta_array(self.est.n_params), ev.figures)
        self._history.append(ev)

    def _evaluate_next(self) -> None:
        if self._scheduler is not None:
            ev = self._scheduler.step(self.channels, self._event)
            if ev is not None:
                self._completed(ev)

    def _finish_evaluations(self) -> None:
        if self._scheduler is not None:
            for ev in self._scheduler.finish(self.channels, self._event):
                self._completed(ev)

    @property
    def _pending(self) -> bool:
        return self._scheduler is not None and self._scheduler.pending is not None

    def lag_ms(self) -> LagStats:
        """p50, p99 and max lag (ms) over the last 200 000 polls that had data."""
        return self._lag.stats()

    # ------------------------------------------------------------------ display
    def snapshot(self) -> SessionSnapshot:
        """The state for a display (small, picklable)."""
        display = self._display
        rate = display.rate.update(self._n)
        if display.h1 is not None:
            display.h1.renew_next(self.channels)
        return SessionSnapshot(
            t_s=self.t_s, fs=self.fs, samples=self._n, rate_sps=rate,
            counters=dict(self.source.counters), lag_ms=self.lag_ms(),
            events=tuple(e for e in self.events if e["kind"] in _SHOWN)[-50:],
            channels=tuple(self._channel_snapshot(k, p) for k, p in enumerate(self.channels)),
            history=self._history.snapshot(), theta_names=self._theta_names(),
            compensation=None if display.compensation is None else display.compensation(),
        )

    def _channel_snapshot(self, k: int, proc: ChannelProcessor) -> ChannelSnapshot:
        grid, h, h_ref = proc.model_response()
        h1 = None if self._display.h1 is None else self._display.h1.get(k)
        return ChannelSnapshot(
            name=proc.name, learning=proc.learning, alarm=proc.detector.active,
            figures=tuple(proc.figures.tolist()),
            peak_figures=tuple(proc.peak_figures.tolist()),
            dominant_hz=abs(proc.dominant) / (2 * math.pi), band_hz=proc.band_hz,
            grid_hz=grid, model=h, reference=h_ref,
            h1_hz=None if h1 is None else h1.freq_hz,
            h1=None if h1 is None else h1.response,
            h1_coherence=None if h1 is None else h1.coherence,
            tracking_rms=proc.tracking_rms, prediction_rms=proc.prediction_rms,
        )

    def _theta_names(self) -> tuple[str, ...]:
        e = self.est
        return tuple([f"a{i}" for i in range(1, e.na + 1)] + [f"b{i}" for i in range(e.nb + 1)]
                     + [f"c{i}" for i in range(1, e.nc + 1)])

    def _maybe_publish(self) -> None:
        if self.fs and self._display.due():
            self._display.publish(self.snapshot())

    # ------------------------------------------------------------------ run
    def run(self, *, duration_s: float | None = None, stop: threading.Event | None = None,
            max_wall_s: float | None = None, idle_stop_s: float | None = None) -> LiveReport:
        """Process until the source ends, ``duration_s`` of stream time, ``stop`` is set,
        ``max_wall_s`` passes, or no data came for ``idle_stop_s`` after the first.
        """
        self.start()
        try:
            while not self._should_stop(duration_s, stop, max_wall_s, idle_stop_s):
                self.step(duration_s=duration_s)
        finally:
            report = self.close()
        return report

    def start(self) -> None:
        """Start the clocks (:meth:`run` does; a caller of :meth:`step` must)."""
        self._clock = _Clock()

    def _should_stop(self, duration_s: float | None, stop: threading.Event | None,
                     max_wall_s: float | None, idle_stop_s: float | None) -> bool:
        clock = self._clock
        assert clock is not None
        now = time.monotonic()
        return bool(
            (stop is not None and stop.is_set())
            or (max_wall_s is not None and now - clock.start[0] >= max_wall_s)
            or (idle_stop_s is not None and clock.last_data is not None
                and now - clock.last_data >= idle_stop_s)
            or self.source.finished
            or (duration_s is not None and self.fs and self._n >= duration_s * self.fs))

    def step(self, *, duration_s: float | None = None, wait_s: float = 0.05) -> None:
        """One poll of the source (waiting up to ``wait_s`` for data unless an
        evaluation is pending), then one evaluation step, a flush of the recording when
        due and a snapshot when due."""
        if self._clock is None:
            self.start()
        assert self._clock is not None
        self._take_events()
        blocks = self._gather(self.source.poll(0.0 if self._pending else wait_s))
        if blocks:
            self._process(blocks, duration_s)
            self._clock.data()
        self._evaluate_next()
        if self.recorder is not None:
            self.recorder.maybe_flush(self.source.counters)
        self._maybe_publish()

    def close(self) -> LiveReport:
        """Complete the evaluations, log the stop, close the recording; the report."""
        if not self._closed:
            self._closed = True
            try:
                self._take_events()
                self._finish_evaluations()
                if self.fs:
                    self._event({"kind": "stop", "counters": dict(self.source.counters),
                                 "lag_ms": self.lag_ms().to_dict()})
            finally:
                if self.recorder is not None:
                    self.recorder.close(self.source.counters)
        return self._report()

    def _report(self) -> LiveReport:
        clock = self._clock or _Clock()
        active_wall, active_cpu = clock.active()
        return LiveReport(
            samples=self._n, stream_s=self.t_s,
            wall_s=time.monotonic() - clock.start[0],
            cpu_s=time.process_time() - clock.start[1],
            counters=dict(self.source.counters), lag_ms=self.lag_ms(),
            alarms=[e for e in self.events if e["kind"] in ("alarm", "clear")],
            final_theta={p.name: (p.estimator.theta if p.estimator is not None else None)
                         for p in self.channels},
            active_wall_s=active_wall, active_cpu_s=active_cpu, setup_ms=self.setup_ms,
            settings=self.settings(),
            detection_started={p.name: p.detection_began for p in self.channels},
        )

    def _gather(self, blocks: list[Block]) -> list[Block]:
        """Wait up to ``batch_s`` for more blocks after the first: the estimators' cost
        is mostly per call, so 2 ms of samples cost about what 1 ms costs."""
        if not blocks or self._batch_s <= 0 or not self.fs:
            return blocks
        want = self._batch_s * self.fs
        deadline = time.monotonic() + self._batch_s
        have = sum(b.samples.shape[0] for b in blocks)
        while have < want:
            left = deadline - time.monotonic()
            if left <= 0:
                break
            more = self.source.poll(left)
            if not more:
                break
            blocks.extend(more)
            have += sum(b.samples.shape[0] for b in more)
        return blocks

    def _ready(self, blocks: list[Block]) -> list[Block] | None:
        """The blocks to process once the channels are set up (the first blocks are held
        until the sample rate is known); None while it is not."""
        if self.fs is not None and self.channels:
            return blocks
        self._held.extend(blocks)
        if self.fs is None and not self._infer_fs():
            return None
        assert self.fs is not None
        self._setup(self.fs)
        blocks, self._held = self._held, []
        self._skip_lag = True
        return blocks

    def _process(self, blocks: list[Block], duration_s: float | None) -> None:
        ready = self._ready(blocks)
        if ready is None or self.fs is None or self._scheduler is None:
            return
        limit = None if duration_s is None else int(round(duration_s * self.fs))
        for first, x in _runs(ready):
            if limit is not None:
                x = x[:max(0, limit - self._n)]
                if not x.shape[0]:
                    break
            if self._next_index is not None and first != self._next_index:
                for proc in self.channels:
                    proc.lost()
            self._next_index = first + x.shape[0]
            if self.recorder is not None:
                self.recorder.samples(first, x)
            self._consume(x, self._scheduler)
        if self._skip_lag:
            # the first poll also built the channels and opened the recording: its lag
            # is start-up, not processing (reported as setup_ms)
            self.setup_ms = (time.time() - ready[-1].arrival_s) * 1e3
            self._skip_lag = False
        else:
            self._lag.note(ready[-1].arrival_s)


def _warm_up(est: EstimatorSettings) -> None:
    """Load the estimator's compiled kernels now, before any data comes."""
    warm_up(["streaming"], na=est.na, nb=est.nb, nc=est.nc, delay=est.delay,
            methods=[est.method])
    BaselineResidual(np.ones(1), np.zeros(1), np.ones(1), 1)(np.zeros(8), np.zeros(8))


def _runs(blocks: list[Block]) -> list[tuple[int, np.ndarray]]:
    """Blocks joined into runs of consecutive sample indices: (first index, samples)."""
    runs: list[tuple[int, list[np.ndarray]]] = []
    nxt = None
    for b in blocks:
        if b.first_index == nxt:
            runs[-1][1].append(b.samples)
        else:
            runs.append((b.first_index, [b.samples]))
        nxt = b.first_index + b.samples.shape[0]
    return [(f, xs[0] if len(xs) == 1 else np.concatenate(xs)) for f, xs in runs]
