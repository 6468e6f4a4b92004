"""What the dashboard's compensation panel shows, gathered while adaptive compensation runs.

Per channel: the RMS tracking error (desired − feedback) over consecutive stretches of
stream time, with compensation and without (the same rig run beside it without a
compensator; for a remote target, which cannot be run twice, the level before its first
compensator), the response of the inverse the target runs now over the band, and the
counts of compensators loaded and of judgements refused.
"""

from __future__ import annotations

import collections
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ehss.live.snapshot import ChannelCompensation, CompensationSnapshot

__all__ = ["CompensationMonitor"]


@dataclass
class _Channel:
    name: str
    rows: collections.deque
    sum_with: float = 0.0
    sum_without: float = 0.0
    n: int = 0
    before_sum: float = 0.0          # desired − feedback before the first compensator
    before_n: int = 0
    design: Any = None
    inverse: np.ndarray | None = None
    loads: int = 0
    refusals: int = 0
    last_reason: str = ""
    model: str = ""
    decisions_seen: int = 0


@dataclass
class CompensationMonitor:
    """Tracking figures and the current inverse of every channel.

    Parameters
    ----------
    channels : sequence of str
    fs : float
        Sample rate, Hz.
    band_hz : (lo, hi)
        Band of the compensation (the inverse's response is shown over it).
    mode : str
        ``"preview"`` or ``"causal"``.
    stretch_s : float
        Length of each stretch of the tracking figures, s of stream time.
    keep : int
        Stretches kept (600 of 0.25 s: the latest 150 s).
    n_freq : int
        Points of the inverse's response, log-spaced over the band.
    """

    channels: Sequence[str]
    fs: float
    band_hz: tuple[float, float]
    mode: str
    stretch_s: float = 0.25
    keep: int = 600
    n_freq: int = 128
    _ch: list[_Channel] = field(init=False, repr=False)
    _n: int = field(init=False, default=0)
    _loads_seen: int = field(init=False, default=0)
    freq_hz: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self._ch = [_Channel(str(name), collections.deque(maxlen=self.keep))
                    for name in self.channels]
        self._index = {ch.name: k for k, ch in enumerate(self._ch)}
        self._stretch = max(1, int(round(self.stretch_s * self.fs)))
        lo = max(self.band_hz[0], 1e-3)
        self.freq_hz = np.geomspace(lo, max(self.band_hz[1], 1.001 * lo), self.n_freq)

    def feed(self, desired: np.ndarray, feedback: np.ndarray,
             feedback_without: np.ndarray | None = None) -> None:
        """Consecutive samples, each array shape (n_channels, n): the desired reference,
        the feedback with compensation and, when the rig runs beside without one, its
        feedback there."""
        desired, feedback = np.atleast_2d(desired), np.atleast_2d(feedback)
        i, n = 0, desired.shape[1]
        while i < n:
            take = min(n - i, self._stretch - self._n % self._stretch)
            part = slice(i, i + take)
            for k, ch in enumerate(self._ch):
                e = desired[k, part] - feedback[k, part]
                ch.sum_with += float(e @ e)
                if feedback_without is not None:
                    w = desired[k, part] - feedback_without[k, part]
                    ch.sum_without += float(w @ w)
                else:
                    ch.sum_without = math.nan
                if ch.loads == 0:
                    ch.before_sum += float(e @ e)
                    ch.before_n += take
                ch.n += take
            self._n += take
            i += take
            if self._n % self._stretch == 0:
                self._close_stretch()

    def _close_stretch(self) -> None:
        t = self._n / self.fs
        for ch in self._ch:
            with_ = math.sqrt(ch.sum_with / ch.n)
            if math.isnan(ch.sum_without):
                # a remote target: the level before its first compensator stands for it
                without = with_ if ch.loads == 0 else math.sqrt(ch.before_sum
                                                                / max(ch.before_n, 1))
            else:
                without = math.sqrt(ch.sum_without / ch.n)
            ch.rows.append((t, with_, without))
            ch.sum_with = ch.sum_without = 0.0
            ch.n = 0

    def update(self, k: int, *, design: Any, loads: int, refusals: int,
               last_reason: str = "", model: str = "") -> None:
        """Channel ``k``'s state: the design the target runs now (anything with
        ``frequency_response(freq_hz)``, or None), compensators loaded, judgements
        refused, why the latest refusal refused, whose model the inverse inverts."""
        ch = self._ch[k]
        if design is not ch.design:
            ch.design = design
            ch.inverse = None if design is None else \
                np.asarray(design.frequency_response(self.freq_hz))
        ch.loads, ch.refusals = int(loads), int(refusals)
        ch.last_reason, ch.model = last_reason, model

    def snapshot(self) -> CompensationSnapshot:
        """The panel's data now."""
        chans = []
        for ch in self._ch:
            rows = np.array(ch.rows).reshape(-1, 3)
            chans.append(ChannelCompensation(
                name=ch.name, t=rows[:, 0].copy(), error_rms=rows[:, 1].copy(),
                error_rms_without=rows[:, 2].copy(), freq_hz=self.freq_hz,
                inverse=ch.inverse, loads=ch.loads, refusals=ch.refusals,
                last_reason=ch.last_reason, model=ch.model))
        return CompensationSnapshot(mode=self.mode, band_hz=(float(self.band_hz[0]),
                                                              float(self.band_hz[1])),
                                    channels=tuple(chans))

    def follow(self, loop: Any) -> None:
        """Take each channel's state from an :class:`~ehss.live.compensate.AdaptiveLoop`
        (its adapters' current designs and judgements, and its loads); what was counted
        before is not counted again."""
        for load in loop.loads[self._loads_seen:]:
            k = self._index[load["channel"]]
            self._ch[k].loads += 1
            self._ch[k].model = load.get("model", "")
        self._loads_seen = len(loop.loads)
        for k, ad in enumerate(loop.adapters):
            ch = self._ch[k]
            log = ad.compensator.log
            for d in log[ch.decisions_seen:]:
                if not d.accepted:
                    ch.refusals += 1
                    ch.last_reason = d.reason
            ch.decisions_seen = len(log)
            self.update(k, design=ad.compensator.current, loads=ch.loads,
                        refusals=ch.refusals, last_reason=ch.last_reason, model=ch.model)
