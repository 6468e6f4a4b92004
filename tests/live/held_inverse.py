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
from typing import Any

import numpy as np

from ehss.live.compensate import CompensationRecord

__all__ = ["Sending", "held"]


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


def held(make_target: Callable[[], Any], sent: list[tuple[int, int, Any, int, int]],
         until_s: float) -> CompensationRecord:
    """Run a fresh ``make_target()`` to its end with the compensators of ``sent`` that
    came before ``until_s``, each handed over at the index it came at: its record, with
    no judgements of its own."""
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
    return CompensationRecord(
        fs=float(target.fs), channels=tuple(target.channels),
        desired=np.hstack([b.desired for b in blocks]),
        drive=np.hstack([b.drive for b in blocks]),
        feedback=np.hstack([b.feedback for b in blocks]),
        decisions={}, loads=[], events=[], settings={})
