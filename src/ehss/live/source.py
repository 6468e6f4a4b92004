"""What every live source hands to the processing: blocks of samples, and counters.

A source (:class:`~ehss.live.udp.UdpSource`, :class:`PacedSource` for the simulated rig
and for recorded files) has a :class:`~ehss.live.layout.RecordLayout`, a sample rate
when it knows one, :meth:`poll` that returns the blocks of samples that have arrived, in
sample order, and a dict of counters (:data:`COUNTERS`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from ehss.errors import ParameterError
from ehss.live.layout import RecordLayout

__all__ = ["COUNTERS", "Block", "Source", "PacedSource", "new_counters"]

#: Counters every source keeps (all start at 0).
COUNTERS = (
    "packets",        # datagrams (or blocks) accepted
    "samples",        # samples delivered to the processing, in order
    "gaps",           # jumps of the sample index given up on (packets never came)
    "lost_samples",   # samples inside those gaps
    "reordered",      # packets that came out of order and were put back in place
    "late",           # packets that came after their place had passed, or twice: dropped
    "malformed",      # datagrams of the wrong size, magic, version, field count, NaN/inf
    "foreign",        # datagrams from a sender not allowed: dropped before parsing
    "truncated",      # datagrams longer than the receive buffer (oversized): dropped
)


def new_counters() -> dict[str, int]:
    """All :data:`COUNTERS` at 0."""
    return dict.fromkeys(COUNTERS, 0)


@dataclass(frozen=True)
class Block:
    """Consecutive samples of the stream.

    Attributes
    ----------
    first_index : int
        Index of the first sample in the stream (0 at the start).
    samples : ndarray, shape (n, n_fields)
        The samples, fields in layout order.
    arrival_s : float
        Wall-clock time (``time.time()``, s) at which the newest of these samples
        arrived (the kernel's receive time for UDP when the system gives it).
    """

    first_index: int
    samples: np.ndarray
    arrival_s: float


class Source(Protocol):
    """The interface of a live source."""

    layout: RecordLayout
    fs: float | None
    counters: dict[str, int]

    def poll(self, timeout_s: float) -> list[Block]:
        """Blocks that arrived, waiting at most ``timeout_s`` for the first."""

    @property
    def finished(self) -> bool:
        """True when the source will deliver nothing more."""

    def close(self) -> None:
        """Release the source's resources."""


class PacedSource:
    """A whole record played to the wall clock (``speed`` × real time).

    Parameters
    ----------
    layout : RecordLayout
    samples : ndarray, shape (n, n_fields)
        The record.
    fs : float
        Its sample rate, Hz.
    speed : float
        Playback speed; ``math.inf`` plays as fast as the consumer takes it.
    block_samples : int
        Samples per block (a packet of the target): 1 ms of samples by default.
    clock : callable, optional
        Monotonic clock in s (tests may pass their own).
    """

    def __init__(
        self, layout: RecordLayout, samples: np.ndarray, fs: float, *, speed: float = 1.0,
        block_samples: int | None = None, clock: Callable[[], float] = time.monotonic,
    ) -> None:
        samples = np.ascontiguousarray(samples, dtype=np.float64)
        if samples.ndim != 2 or samples.shape[1] != layout.n_fields:
            raise ParameterError(
                f"record has shape {samples.shape}, must be (n, {layout.n_fields})"
            )
        if not (isinstance(fs, (int, float)) and math.isfinite(fs) and fs > 0):
            raise ParameterError(f"fs={fs!r} must be a positive number (Hz)")
        if not (isinstance(speed, (int, float)) and speed > 0 and not math.isnan(speed)):
            raise ParameterError(f"speed={speed!r} must be > 0 (inf: as fast as possible)")
        if block_samples is None:
            block_samples = max(1, round(fs / 1000.0))
        if not isinstance(block_samples, int) or block_samples < 1:
            raise ParameterError(f"block_samples={block_samples!r} must be an integer >= 1")
        self.layout = layout
        self.fs = float(fs)
        self.counters = new_counters()
        self._x = samples
        self._speed = float(speed)
        self._block = block_samples
        self._clock = clock
        self._t0: float | None = None
        self._next = 0

    @property
    def finished(self) -> bool:
        return self._next >= self._x.shape[0]

    def _due(self, now: float) -> int:
        if math.isinf(self._speed):
            # as fast as possible: about 0.1 s of record per poll keeps blocks large
            return min(self._x.shape[0], self._next + max(self._block, int(0.1 * self.fs)))
        t0 = now if self._t0 is None else self._t0
        due = int((now - t0) * self._speed * self.fs)
        return min(self._x.shape[0], due)

    def poll(self, timeout_s: float) -> list[Block]:
        if self.finished:
            return []
        now = self._clock()
        if self._t0 is None:
            self._t0 = now
        due = self._due(now)
        if due - self._next < self._block and due < self._x.shape[0]:
            # wait for the next whole block, or the timeout
            wait = (self._next + self._block) / (self._speed * self.fs) - (now - self._t0)
            if wait > 0:
                time.sleep(min(wait, max(timeout_s, 0.0)))
            now = self._clock()
            due = self._due(now)
        blocks = []
        arrival = time.time()
        block = self._x.shape[0] if math.isinf(self._speed) else self._block
        while self._next < due and (due - self._next >= self._block or due == self._x.shape[0]):
            stop = min(self._next + block, due)
            blocks.append(Block(self._next, self._x[self._next:stop], arrival))
            self.counters["packets"] += 1
            self.counters["samples"] += stop - self._next
            self._next = stop
        return blocks

    def close(self) -> None:
        self._next = self._x.shape[0]
