"""The inverse built before a change, held: what a rig without adaptation would have run.

An adaptive run's target is wrapped in :class:`Sending`, which keeps every compensator
handed to it with the sample index at which it came. :func:`held` then runs a fresh
target of the same test, handing it, at the same indices, the compensators that came
before the change and nothing after: up to the change it is the adaptive run again (the
same compensators on the same samples, the same sensor noise), from it on the
compensators of before stay. It needs no second adaptive run, only the target's own
simulation.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["Sending", "HeldRun", "held"]


class Sending:
    """A target that keeps what it was handed: ``sent`` holds ``(index, channel,
    compensator, apply_index, crossfade)`` in order, ``index`` the target's sample index
    when it came. Everything else is the wrapped target's."""

    def __init__(self, target: Any) -> None:
        self.target = target
        self.sent: list[tuple[int, int, Any, int, int]] = []

    def __getattr__(self, name: str) -> Any:
        return getattr(self.target, name)

    def load(self, channel: int, compensator: Any, apply_index: int, crossfade: int) -> bool:
        self.sent.append((self.target.index, channel, compensator, apply_index, crossfade))
        return self.target.load(channel, compensator, apply_index, crossfade)


@dataclass
class HeldRun:
    """Desired reference and feedback of every channel, each shape (n_channels, n)."""

    fs: float
    desired: np.ndarray = field(repr=False)
    feedback: np.ndarray = field(repr=False)

    def tracking_rms(self, t0_s: float, t1_s: float) -> np.ndarray:
        """RMS of desired − feedback of each channel over ``[t0_s, t1_s)``."""
        a, b = int(round(t0_s * self.fs)), int(round(t1_s * self.fs))
        e = self.desired[:, a:b] - self.feedback[:, a:b]
        return np.sqrt(np.mean(e * e, axis=1))


def held(make_target: Callable[[], Any], sent: list[tuple[int, int, Any, int, int]],
         until_s: float) -> HeldRun:
    """Run a fresh ``make_target()`` to its end with the compensators of ``sent`` that
    came before ``until_s``, each handed over at the index it came at."""
    target = make_target()
    until = int(round(until_s * target.fs))
    blocks = []
    for index, channel, compensator, apply_index, crossfade in sent:
        if index >= until:
            break
        if index > target.index:
            blocks.append(target.step(index - target.index))
        target.load(channel, compensator, apply_index, crossfade)
    while not target.finished:
        blocks.append(target.step(target.n_samples - target.index))
    return HeldRun(float(target.fs), np.hstack([b.desired for b in blocks]),
                   np.hstack([b.feedback for b in blocks]))
