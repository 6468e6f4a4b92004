"""A live session: samples from a source through the channels' estimators and change
detection into the recording, with snapshots for a display.

The loop never waits on a display: a snapshot is handed to ``publish`` (which must not
block; the dashboard's queue drops a snapshot it cannot take, never samples), and the
recording is flushed at most every ``flush_s``. The source's own buffer (the socket's
receive buffer for UDP, 8 MiB) absorbs the time a flush or a snapshot takes.
"""

from __future__ import annotations

import collections
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

import ehss
from ehss._files import check_writable
from ehss.errors import DataError, ParameterError
from ehss.live.channel import ChannelProcessor, EstimatorSettings
from ehss.live.detect import FIGURES, BaselineResidual, DetectionSettings
from ehss.live.recording import LiveRecorder
from ehss.live.source import Block, Source

__all__ = ["LiveReport", "LiveSession"]

_LAG_KEEP = 200_000


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
    lag_ms : dict
        ``p50``, ``p99``, ``max`` of the estimator's lag behind the newest packet
        (from its arrival to the end of its processing), ms.
    alarms : list of dict
        Alarm and clear events.
    final_theta : dict
        θ̂ of each channel at the end.
    active_wall_s, active_cpu_s : float
        Wall-clock and CPU time from the first block of data to the last (the CPU share
        of the processing is their ratio).
    """

    samples: int
    stream_s: float
    wall_s: float
    cpu_s: float
    counters: dict
    lag_ms: dict
    alarms: list
    final_theta: dict = field(repr=False)
    active_wall_s: float = math.nan
    active_cpu_s: float = math.nan


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
        Receives a snapshot dict every ``display_s`` of wall time; must not block.
    display_s : float
    h1 : bool
        Compute the sliding H1 estimates for the snapshots (for the dashboard): one
        channel per snapshot, in turn, so that a snapshot costs at most one Welch
        estimate of the processing's time.
    settings : dict, optional
        Extra JSON-able settings to store with the recording.
    log : callable, optional
        Receives each event dict as it happens (e.g. to print alarms).
    batch_s : float
        After the first block of a poll, wait up to this long for more before processing
        (the estimators' cost is mostly per call): the lag behind the newest datagram is
        unchanged, an older one waits at most this much longer.
    """

    def __init__(
        self, source: Source, *, est: EstimatorSettings, det: DetectionSettings,
        baselines: dict[str, ehss.ArmaxModel] | None = None, record=None,
        update_s: float = 0.1, publish: Callable[[dict], None] | None = None,
        display_s: float = 0.5, h1: bool = False, settings: dict | None = None,
        log: Callable[[dict], None] | None = None, batch_s: float = 0.002,
    ) -> None:
        if not (isinstance(update_s, (int, float)) and update_s > 0):
            raise ParameterError(f"update_s={update_s!r} must be > 0 (s)")
        self.source = source
        self.layout = source.layout
        self.est, self.det = est, det
        self.baselines = dict(baselines or {})
        unknown = set(self.baselines) - set(self.layout.channels)
        if unknown:
            raise ParameterError(f"baselines for unknown channels {sorted(unknown)}; the "
                                 f"stream has {', '.join(self.layout.channels)}")
        if record is not None:
            record = check_writable(record)
            if record.exists():
                raise DataError(f"{str(record)!r} exists: a recording is never overwritten")
        self._record_path = record
        self._update_s = float(update_s)
        self._publish = publish
        self._display_s = float(display_s)
        self._with_h1 = bool(h1)
        if not (isinstance(batch_s, (int, float)) and 0 <= batch_s < 1):
            raise ParameterError(f"batch_s={batch_s!r} must be in [0, 1) s")
        self._batch_s = float(batch_s)
        self._settings = dict(settings or {})
        self._log = log
        self.fs: float | None = source.fs
        # load the estimator's compiled kernels now, before any data comes
        warm = ehss.RelsEstimator(na=self.est.na, nb=self.est.nb, nc=self.est.nc,
                                  delay=self.est.delay, method=self.est.method)
        warm.update_many(np.zeros(64), np.zeros(64))
        BaselineResidual(np.ones(1), np.zeros(1), np.ones(1), 1)(np.zeros(8), np.zeros(8))
        self.channels: list[ChannelProcessor] = []
        self.recorder: LiveRecorder | None = None
        self.events: list[dict] = []
        self._held: list[Block] = []
        self._n = 0
        self._next_eval = 0
        self._eval_n = 0
        self._lag = np.empty(_LAG_KEEP)
        self._n_lag = 0
        self._hist: collections.deque = collections.deque(maxlen=600)
        self._h1_cache: dict[int, ehss.FrequencyResponse | None] = {}
        self._h1_turn = 0
        self._last_publish = -math.inf
        self._rate = (time.monotonic(), 0)
        self.rate_sps = 0.0
        self._evals: dict | None = None
        self._skip_lag = False
        self.setup_ms = math.nan
        self._active0: tuple[float, float] | None = None
        self._active1: tuple[float, float] | None = None

    # ------------------------------------------------------------------ setup
    def _infer_fs(self) -> bool:
        ti = self.layout.time_index
        x = np.concatenate([b.samples for b in self._held])
        if ti is None:
            raise ParameterError("the sample rate is unknown: give --fs, or send a field 't'")
        if x.shape[0] < 3:
            return False
        dt = np.diff(x[:, ti])
        step = float(np.median(dt))
        if not (math.isfinite(step) and step > 0):
            raise ParameterError("the 't' field does not increase: give --fs")
        self.fs = 1.0 / step
        return True

    def _setup(self) -> None:
        fs = self.fs
        self._eval_n = max(1, int(round(self._update_s * fs)))
        self._next_eval = self._eval_n
        self.channels = [
            ChannelProcessor(name, fs, self.est, self.det, self.baselines.get(name))
            for name in self.layout.channels
        ]
        if self._record_path is not None:
            settings = {"estimator": self.est.to_dict(), "detection": self.det.to_dict(),
                        "update_s": self._update_s, "forgetting": self.est.lam(fs),
                        **self._settings}
            self.recorder = LiveRecorder(self._record_path, self.layout, fs,
                                         self.est.n_params, settings)
        self._event({"kind": "start", "fs": fs, "channels": list(self.layout.channels),
                     "forgetting": self.est.lam(fs)})

    # ------------------------------------------------------------------ events
    def _event(self, record: dict, t_s: float | None = None) -> None:
        if t_s is None:
            t_s = self._n / self.fs if self.fs else 0.0
        record = {"t_s": t_s, "wall": time.time(), **record}
        self.events.append(record)
        if self.recorder is not None:
            self.recorder.event(record)
        if self._log is not None:
            self._log(record)

    # ------------------------------------------------------------------ processing
    def _consume(self, x: np.ndarray) -> None:
        cols = np.ascontiguousarray(x.T)
        ri, fi = self.layout.ref_index, self.layout.fb_index
        i, n = 0, x.shape[0]
        while i < n:
            take = min(n - i, self._next_eval - self._n)
            for k, proc in enumerate(self.channels):
                proc.feed(cols[ri[k], i:i + take], cols[fi[k], i:i + take])
            self._n += take
            i += take
            if self._n == self._next_eval:
                self._capture()
                self._next_eval += self._eval_n

    # Evaluations: at each boundary θ̂ of every channel is captured (cheap); the
    # comparisons, one channel at a time, run between polls, so that a poll never
    # waits for all channels' figures. The next boundary completes any left over.
    def _capture(self) -> None:
        self._finish_evaluations()
        c = len(self.channels)
        thetas = [proc.capture() for proc in self.channels]
        self._evals = {
            "t": self._n / self.fs, "theta": thetas, "next": 0, "may_set_up": True,
            "figures": np.full((c, len(FIGURES)), np.nan),
            "track": np.array([p.tracking_rms for p in self.channels]),
        }

    def _evaluate_next(self) -> None:
        ev = self._evals
        k = ev["next"]
        proc = self.channels[k]
        t = ev["t"]
        change = proc.evaluate(t, ev["theta"][k], may_set_up=ev["may_set_up"])
        ev["may_set_up"] = ev["may_set_up"] and not proc.just_set_up  # one per boundary
        for msg in proc.messages:
            self._event({"kind": "message", "channel": proc.name, "text": msg}, t)
        proc.messages.clear()
        ev["figures"][k] = proc.figures
        if change is not None:
            s = proc.dominant
            self._event({
                "kind": change, "channel": proc.name,
                **{name: float(v) for name, v in zip(FIGURES, proc.figures, strict=True)},
                "exceeded": proc.detector.exceeded(proc.figures),
                "dominant_hz": abs(s) / (2 * math.pi),
                "dominant_damping": -s.real / abs(s) if abs(s) > 0 else math.nan,
            }, t)
        ev["next"] += 1
        if ev["next"] == len(self.channels):
            theta = np.array([np.full(self.est.n_params, np.nan) if th is None else th
                              for th in ev["theta"]])
            if self.recorder is not None:
                self.recorder.estimate(t, theta, ev["figures"])
            self._hist.append((t, theta, ev["track"], ev["figures"]))
            self._evals = None

    def _finish_evaluations(self) -> None:
        while self._evals is not None:
            self._evaluate_next()

    def _note_lag(self, arrival: float) -> None:
        lag = time.time() - arrival
        self._lag[self._n_lag % _LAG_KEEP] = lag
        self._n_lag += 1

    def lag_ms(self) -> dict[str, float]:
        """p50, p99 and max lag (ms) over the last 200 000 polls that had data."""
        lags = self._lag[:min(self._n_lag, _LAG_KEEP)]
        if not lags.size:
            return {"p50": math.nan, "p99": math.nan, "max": math.nan}
        p50, p99 = np.percentile(lags, [50, 99]) * 1e3
        return {"p50": float(p50), "p99": float(p99), "max": float(lags.max() * 1e3)}

    # ------------------------------------------------------------------ display
    def snapshot(self) -> dict:
        """The state for a display (small, picklable)."""
        now = time.monotonic()
        t0, n0 = self._rate
        if now - t0 >= 1.0:
            self.rate_sps = (self._n - n0) / (now - t0)
            self._rate = (now, self._n)
        if self._with_h1 and self.channels:
            k = self._h1_turn % len(self.channels)
            self._h1_cache[k] = self.channels[k].h1()
            self._h1_turn += 1
        chans = []
        for k, proc in enumerate(self.channels):
            grid, h, h_ref = proc.model_response()
            h1 = self._h1_cache.get(k)
            s = proc.dominant
            chans.append({
                "name": proc.name,
                "learning": proc.learning,
                "alarm": proc.detector.active,
                "figures": proc.figures.tolist(),
                "peak_figures": proc.peak_figures.tolist(),
                "dominant_hz": abs(s) / (2 * math.pi),
                "band_hz": proc.band_hz,
                "grid_hz": grid,
                "model": h,
                "reference": h_ref,
                "h1_hz": None if h1 is None else h1.freq_hz,
                "h1": None if h1 is None else h1.response,
                "h1_coherence": None if h1 is None else h1.coherence,
                "tracking_rms": proc.tracking_rms,
                "prediction_rms": proc.prediction_rms,
            })
        hist = list(self._hist)
        history = {
            "t": np.array([h[0] for h in hist]),
            "theta": np.array([h[1] for h in hist]) if hist else np.empty((0, 0, 0)),
            "tracking": np.array([h[2] for h in hist]) if hist else np.empty((0, 0)),
            "figures": np.array([h[3] for h in hist]) if hist else np.empty((0, 0, 3)),
        }
        return {
            "t_s": self._n / self.fs if self.fs else 0.0,
            "fs": self.fs,
            "samples": self._n,
            "rate_sps": self.rate_sps,
            "counters": dict(self.source.counters),
            "lag_ms": self.lag_ms(),
            "events": [e for e in self.events if e["kind"] in ("alarm", "clear", "message")]
            [-50:],
            "channels": chans,
            "history": history,
            "theta_names": self._theta_names(),
        }

    def _theta_names(self) -> list[str]:
        e = self.est
        return ([f"a{i}" for i in range(1, e.na + 1)] + [f"b{i}" for i in range(e.nb + 1)]
                + [f"c{i}" for i in range(1, e.nc + 1)])

    # ------------------------------------------------------------------ run
    def run(self, *, duration_s: float | None = None, stop: threading.Event | None = None,
            max_wall_s: float | None = None, idle_stop_s: float | None = None) -> LiveReport:
        """Process until the source ends, ``duration_s`` of stream time, ``stop`` is set,
        ``max_wall_s`` passes, or no data came for ``idle_stop_s`` after the first.
        """
        wall0, cpu0 = time.monotonic(), time.process_time()
        last_data = None
        try:
            while True:
                now = time.monotonic()
                if stop is not None and stop.is_set():
                    break
                if max_wall_s is not None and now - wall0 >= max_wall_s:
                    break
                if idle_stop_s is not None and last_data is not None \
                        and now - last_data >= idle_stop_s:
                    break
                if self.source.finished:
                    break
                if duration_s is not None and self.fs and self._n >= duration_s * self.fs:
                    break
                # a pending evaluation step first when data waits, else poll briefly
                blocks = self.source.poll(0.0 if self._evals is not None else 0.05)
                blocks = self._gather(blocks)
                if blocks:
                    if self._active0 is None:
                        self._active0 = (time.monotonic(), time.process_time())
                    self._process(blocks, duration_s)
                    last_data = time.monotonic()
                    self._active1 = (last_data, time.process_time())
                if self._evals is not None:
                    self._evaluate_next()
                if self.recorder is not None:
                    self.recorder.maybe_flush(self.source.counters)
                if self._publish is not None and self.fs and \
                        time.monotonic() - self._last_publish >= self._display_s:
                    self._last_publish = time.monotonic()
                    self._publish(self.snapshot())
        finally:
            self._finish_evaluations()
            if self.fs:
                self._event({"kind": "stop", "counters": dict(self.source.counters),
                             "lag_ms": self.lag_ms()})
            if self.recorder is not None:
                self.recorder.close(self.source.counters)
        final = {p.name: (p.estimator.theta if p.estimator is not None else None)
                 for p in self.channels}
        return LiveReport(
            samples=self._n, stream_s=self._n / self.fs if self.fs else 0.0,
            wall_s=time.monotonic() - wall0, cpu_s=time.process_time() - cpu0,
            counters=dict(self.source.counters), lag_ms=self.lag_ms(),
            alarms=[e for e in self.events if e["kind"] in ("alarm", "clear")],
            final_theta=final,
            active_wall_s=(self._active1[0] - self._active0[0]) if self._active0 else math.nan,
            active_cpu_s=(self._active1[1] - self._active0[1]) if self._active0 else math.nan,
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

    def _process(self, blocks: list[Block], duration_s: float | None) -> None:
        if self.fs is None or not self.channels:
            self._held.extend(blocks)
            if self.fs is None and not self._infer_fs():
                return
            self._setup()
            blocks, self._held = self._held, []
            self._skip_lag = True
        limit = None if duration_s is None else int(round(duration_s * self.fs))
        for first, x in _runs(blocks):
            if limit is not None:
                x = x[:max(0, limit - self._n)]
                if not x.shape[0]:
                    break
            if self.recorder is not None:
                self.recorder.samples(first, x)
            self._consume(x)
        if self._skip_lag:
            # the first poll also built the channels and opened the recording: its lag
            # is start-up, not processing (reported as setup_ms)
            self.setup_ms = (time.time() - blocks[-1].arrival_s) * 1e3
            self._skip_lag = False
        else:
            self._note_lag(blocks[-1].arrival_s)


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
