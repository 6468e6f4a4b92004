"""The parts a live session is made of, each with one job and testable alone.

* :class:`LagMeter`: the processing's lag behind the newest packet, as percentiles.
* :class:`RateMeter`: samples per second of wall time.
* :class:`SlidingH1`: the channels' sliding H1 estimates, one channel per call in turn,
  so that a snapshot costs at most one Welch estimate of the processing's time.
* :class:`EvaluationScheduler`: the evaluation boundaries (every ``update_s`` of stream
  time), θ̂ captured at each, the comparisons run one channel per step between polls.
* :class:`EvaluationHistory`: the latest evaluations, as arrays for the displays.
"""

from __future__ import annotations

import collections
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

import ehss
from ehss.live.channel import ChannelProcessor
from ehss.live.detect import FIGURES
from ehss.live.snapshot import HistorySnapshot, LagStats

__all__ = ["Evaluation", "EvaluationHistory", "EvaluationScheduler", "LagMeter",
           "RateMeter", "SlidingH1"]


class LagMeter:
    """Lags (s) of the latest ``keep`` polls that had data, as ms percentiles."""

    def __init__(self, keep: int = 200_000) -> None:
        self._lag = np.empty(keep)
        self._n = 0

    def note(self, arrival_s: float, now_s: float | None = None) -> None:
        """One poll's lag: from ``arrival_s`` (``time.time()`` of the newest sample's
        arrival) to ``now_s`` (default: now)."""
        now_s = time.time() if now_s is None else now_s
        self._lag[self._n % self._lag.size] = now_s - arrival_s
        self._n += 1

    def stats(self) -> LagStats:
        """p50, p99 and max, ms (NaN before the first)."""
        lags = self._lag[:min(self._n, self._lag.size)]
        if not lags.size:
            return LagStats()
        p50, p99 = np.percentile(lags, [50, 99]) * 1e3
        return LagStats(float(p50), float(p99), float(lags.max() * 1e3))


class RateMeter:
    """Samples per second, measured over at least ``period_s`` of the clock."""

    def __init__(self, period_s: float = 1.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self._period = float(period_s)
        self._clock = clock
        self._t0, self._n0 = clock(), 0
        self.rate = 0.0

    def update(self, n: int) -> float:
        """The rate, given ``n`` samples so far (renewed once per period)."""
        now = self._clock()
        if now - self._t0 >= self._period:
            self.rate = (n - self._n0) / (now - self._t0)
            self._t0, self._n0 = now, n
        return self.rate


class SlidingH1:
    """The latest sliding H1 estimate of each channel, renewed one channel per call."""

    def __init__(self) -> None:
        self._cache: dict[int, ehss.FrequencyResponse | None] = {}
        self._turn = 0

    def renew_next(self, channels: Sequence[ChannelProcessor]) -> None:
        """Estimate the next channel's H1 in turn."""
        if channels:
            k = self._turn % len(channels)
            self._cache[k] = channels[k].h1()
            self._turn += 1

    def get(self, k: int) -> ehss.FrequencyResponse | None:
        return self._cache.get(k)


@dataclass
class Evaluation:
    """One evaluation of all channels at stream time ``t``: θ̂ captured at its boundary,
    the figures filled in channel by channel (``done`` of them so far)."""

    t: float
    theta: list[np.ndarray | None]
    tracking: np.ndarray
    figures: np.ndarray
    done: int = 0
    may_set_up: bool = True

    def theta_array(self, n_params: int) -> np.ndarray:
        """θ̂ of every channel, shape (C, P); NaN where a channel has none yet."""
        return np.array([np.full(n_params, np.nan) if th is None else th
                         for th in self.theta])


#: Receives (event, stream time) of each change and message of an evaluation.
Emit = Callable[[dict, float], None]


class EvaluationScheduler:
    """Evaluations every ``every`` samples.

    At each boundary θ̂ of every channel is captured (cheap); the comparisons, one
    channel per :meth:`step`, run between polls, so that a poll never waits for all
    channels' figures. The next boundary completes any left over.
    """

    def __init__(self, every: int, fs: float) -> None:
        self.every = int(every)
        self.fs = float(fs)
        self.next_boundary = self.every
        self.pending: Evaluation | None = None

    def capture(self, n: int, channels: Sequence[ChannelProcessor],
                emit: Emit) -> list[Evaluation]:
        """At the boundary ``n`` (samples): finish the pending evaluation, capture a new
        one; returns the evaluations completed."""
        done = self.finish(channels, emit)
        self.pending = Evaluation(
            t=n / self.fs, theta=[proc.capture() for proc in channels],
            tracking=np.array([p.tracking_rms for p in channels]),
            figures=np.full((len(channels), len(FIGURES)), np.nan))
        self.next_boundary += self.every
        return done

    def step(self, channels: Sequence[ChannelProcessor], emit: Emit) -> Evaluation | None:
        """Compare the next channel of the pending evaluation; the evaluation once it is
        complete, else None."""
        ev = self.pending
        if ev is None:
            return None
        proc = channels[ev.done]
        change = proc.evaluate(ev.t, ev.theta[ev.done], may_set_up=ev.may_set_up)
        ev.may_set_up = ev.may_set_up and not proc.just_set_up  # one per boundary
        for msg in proc.messages:
            emit({"kind": "message", "channel": proc.name, "text": msg}, ev.t)
        proc.messages.clear()
        ev.figures[ev.done] = proc.figures
        if change is not None:
            emit(_change_event(change, proc), ev.t)
        ev.done += 1
        if ev.done < len(channels):
            return None
        self.pending = None
        return ev

    def finish(self, channels: Sequence[ChannelProcessor], emit: Emit) -> list[Evaluation]:
        """Complete the pending evaluation, if any."""
        done = []
        while self.pending is not None:
            ev = self.step(channels, emit)
            if ev is not None:
                done.append(ev)
        return done


def _change_event(kind: str, proc: ChannelProcessor) -> dict:
    s = proc.dominant
    return {
        "kind": kind, "channel": proc.name,
        **{name: float(v) for name, v in zip(FIGURES, proc.figures, strict=True)},
        "exceeded": proc.detector.exceeded(proc.figures),
        "dominant_hz": abs(s) / (2 * math.pi),
        "dominant_damping": -s.real / abs(s) if abs(s) > 0 else math.nan,
    }


@dataclass
class EvaluationHistory:
    """The latest ``keep`` evaluations (θ̂, tracking and figures per channel)."""

    n_params: int
    keep: int = 600
    _rows: collections.deque = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self._rows = collections.deque(maxlen=self.keep)

    def append(self, ev: Evaluation) -> None:
        self._rows.append((ev.t, ev.theta_array(self.n_params), ev.tracking, ev.figures))

    def __len__(self) -> int:
        return len(self._rows)

    def snapshot(self) -> HistorySnapshot:
        rows = list(self._rows)
        if not rows:
            return HistorySnapshot.empty(len(FIGURES))
        return HistorySnapshot(t=np.array([r[0] for r in rows]),
                               theta=np.array([r[1] for r in rows]),
                               tracking=np.array([r[2] for r in rows]),
                               figures=np.array([r[3] for r in rows]))
