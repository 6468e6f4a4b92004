"""What a live session shows: typed, frozen snapshots for the displays and the report.

:meth:`~ehss.live.session.LiveSession.snapshot` returns a :class:`SessionSnapshot`; the
dashboard (in a process of its own: every class here pickles), the terminal summary and
the JSON report read it by attribute. :meth:`SessionSnapshot.to_dict` gives the plain,
JSON-able form.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = [
    "ChannelCompensation",
    "ChannelSnapshot",
    "CompensationSnapshot",
    "HistorySnapshot",
    "LagStats",
    "SessionSnapshot",
]


def _list(x: np.ndarray | None) -> list | None:
    return None if x is None else np.asarray(x).tolist()


@dataclass(frozen=True)
class LagStats:
    """The processing's lag behind the newest packet (from its arrival to the end of its
    processing), ms: median, 99th percentile and largest."""

    p50: float = math.nan
    p99: float = math.nan
    max: float = math.nan

    def to_dict(self) -> dict[str, float]:
        return {"p50": self.p50, "p99": self.p99, "max": self.max}


@dataclass(frozen=True)
class ChannelSnapshot:
    """One channel's state.

    Attributes
    ----------
    name : str
    learning, alarm : bool
    figures, peak_figures : tuple of float
        The change figures (:data:`ehss.live.detect.FIGURES`) now, and their peaks.
    dominant_hz : float
    band_hz : (lo, hi) or None
    grid_hz : ndarray
        Frequencies of ``model`` and ``reference``.
    model, reference : ndarray (complex) or None
        Response of the current model and of the reference (baseline) on ``grid_hz``.
    h1_hz, h1, h1_coherence : ndarray or None
        The sliding H1 estimate (None until the channel's turn came).
    tracking_rms, prediction_rms : float
    """

    name: str
    learning: bool
    alarm: bool
    figures: tuple[float, ...]
    peak_figures: tuple[float, ...]
    dominant_hz: float
    band_hz: tuple[float, float] | None
    grid_hz: np.ndarray = field(repr=False)
    model: np.ndarray | None = field(repr=False)
    reference: np.ndarray | None = field(repr=False)
    h1_hz: np.ndarray | None = field(repr=False, default=None)
    h1: np.ndarray | None = field(repr=False, default=None)
    h1_coherence: np.ndarray | None = field(repr=False, default=None)
    tracking_rms: float = math.nan
    prediction_rms: float = math.nan

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name, "learning": self.learning, "alarm": self.alarm,
            "figures": list(self.figures), "peak_figures": list(self.peak_figures),
            "dominant_hz": self.dominant_hz,
            "band_hz": None if self.band_hz is None else list(self.band_hz),
            "grid_hz": _list(self.grid_hz), "h1_hz": _list(self.h1_hz),
            "tracking_rms": self.tracking_rms, "prediction_rms": self.prediction_rms,
        }


@dataclass(frozen=True)
class HistorySnapshot:
    """The latest evaluations of all channels.

    Attributes
    ----------
    t : ndarray, shape (m,)
        Stream time of each evaluation, s.
    theta : ndarray, shape (m, C, P)
    tracking : ndarray, shape (m, C)
        RMS of reference − feedback of each channel.
    figures : ndarray, shape (m, C, len(FIGURES))
    """

    t: np.ndarray
    theta: np.ndarray
    tracking: np.ndarray
    figures: np.ndarray

    @classmethod
    def empty(cls, n_figures: int) -> HistorySnapshot:
        return cls(np.empty(0), np.empty((0, 0, 0)), np.empty((0, 0)),
                   np.empty((0, 0, n_figures)))


@dataclass(frozen=True)
class ChannelCompensation:
    """One channel's adaptive compensation, for the dashboard's panel.

    Attributes
    ----------
    name : str
    t : ndarray, shape (m,)
        End of each stretch of the tracking figures, stream time in s.
    error_rms : ndarray, shape (m,)
        RMS of desired − feedback over each stretch, with compensation.
    error_rms_without : ndarray, shape (m,)
        The same without compensation (the rig run beside it without a compensator; for
        a remote target the level before its first compensator, NaN until then).
    freq_hz : ndarray
        Frequencies over the band of the current inverse's response.
    inverse : ndarray (complex) or None
        Response of the inverse the target runs now (None before the first one).
    loads, refusals : int
        Compensators sent so far, and judgements refused.
    last_reason : str
        Why the latest refusal refused ("" if none yet).
    model : str
        Whose model the current inverse inverts (``"estimator"`` or ``"tracker"``), or
        ``"correction"`` while a correction of it after a change runs.
    """

    name: str
    t: np.ndarray = field(repr=False)
    error_rms: np.ndarray = field(repr=False)
    error_rms_without: np.ndarray = field(repr=False)
    freq_hz: np.ndarray = field(repr=False)
    inverse: np.ndarray | None = field(repr=False)
    loads: int = 0
    refusals: int = 0
    last_reason: str = ""
    model: str = ""


@dataclass(frozen=True)
class CompensationSnapshot:
    """The compensation of all channels: its mode and band, each channel's state."""

    mode: str
    band_hz: tuple[float, float]
    channels: tuple[ChannelCompensation, ...]


@dataclass(frozen=True)
class SessionSnapshot:
    """The state of a live session for a display (small, picklable).

    Attributes
    ----------
    t_s : float
        Stream time processed, s.
    fs : float or None
    samples : int
        Samples processed per channel.
    rate_sps : float
        Samples per second per channel over the last second of wall time.
    counters : dict
        The source's counters.
    lag_ms : LagStats
    events : tuple of dict
        The latest alarms, clears and messages, and with adaptive compensation its
        events: compensators loaded (``"compensator"``; ``"model": "correction"`` for a
        correction after a change), refused, its alarms and clears, and the changes of
        a loop its trigger flagged (``"compensator_change"``) or took for a new test
        level (``"compensator_level"``); at most 50.
    channels : tuple of ChannelSnapshot
    history : HistorySnapshot
    theta_names : tuple of str
        Names of θ̂'s entries (a1.., b0.., c1..).
    compensation : CompensationSnapshot or None
        With adaptive compensation running in the session.
    """

    t_s: float
    fs: float | None
    samples: int
    rate_sps: float
    counters: dict[str, int]
    lag_ms: LagStats
    events: tuple[dict, ...]
    channels: tuple[ChannelSnapshot, ...]
    history: HistorySnapshot = field(repr=False)
    theta_names: tuple[str, ...] = ()
    compensation: CompensationSnapshot | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-able form (responses and the history left out: they are for plots)."""
        return {
            "t_s": self.t_s, "fs": self.fs, "samples": self.samples,
            "rate_sps": self.rate_sps, "counters": dict(self.counters),
            "lag_ms": self.lag_ms.to_dict(), "events": list(self.events),
            "channels": [ch.to_dict() for ch in self.channels],
            "theta_names": list(self.theta_names),
        }
