"""Terminal summary of a live session (rich), for headless use."""

from __future__ import annotations

import math
from typing import TextIO

from rich.console import Console
from rich.live import Live
from rich.table import Table

from ehss.live.snapshot import SessionSnapshot

__all__ = ["TerminalSummary", "summary_table"]


def _fmt(x: float | None, spec: str) -> str:
    return "–" if x is None or not math.isfinite(x) else format(x, spec)


def summary_table(snap: SessionSnapshot) -> Table:
    """One row per channel: state, the test (its statistic over its threshold: an alarm
    at 1), the figures, dominant mode, tracking; packet counters and lag in the
    caption."""
    c = snap.counters
    lag = snap.lag_ms
    table = Table(
        title=f"ehss live  t = {snap.t_s:.1f} s  fs = {snap.fs or math.nan:g} Hz  "
        f"{snap.rate_sps:.0f} samples/s per channel",
        caption=(f"packets {c['packets']}  gaps {c['gaps']} (lost {c['lost_samples']})  "
                 f"reordered {c['reordered']}  late {c['late']}  malformed {c['malformed']}  "
                 f"foreign {c['foreign']}  truncated {c['truncated']}  lag p50/p99 "
                 f"{_fmt(lag.p50, '.1f')}/{_fmt(lag.p99, '.1f')} ms"),
    )
    for col in ("ch", "state", "test", "FRF dist dB", "gain dB", "pole shift", "dominant Hz",
                "tracking rms", "pred. err rms"):
        table.add_column(col, justify="right")
    for ch in snap.channels:
        f = ch.figures
        state = ("[bold red]ALARM" if ch.alarm else
                 "learning" if ch.learning else "[green]ok")
        table.add_row(ch.name, state, _fmt(f[3], ".2f"), _fmt(f[0], ".2f"), _fmt(f[1], "+.2f"),
                      _fmt(f[2], ".3f"), _fmt(ch.dominant_hz, ".1f"),
                      _fmt(ch.tracking_rms, ".3g"), _fmt(ch.prediction_rms, ".3g"))
    return table


class TerminalSummary:
    """A table refreshed in place on a terminal (by rich's own thread, twice a second:
    :meth:`update` only hands the table over); a table every 10 s of stream time on
    anything else."""

    def __init__(self, stream: TextIO) -> None:
        self._console = Console(file=stream)
        self._live: Live | None = None
        if self._console.is_terminal:
            self._live = Live(console=self._console, auto_refresh=True, refresh_per_second=2,
                              transient=False)
            self._live.start()
        self._last_plain = -math.inf

    def update(self, snap: SessionSnapshot) -> None:
        table = summary_table(snap)
        if self._live is not None:
            self._live.update(table)
        elif snap.t_s - self._last_plain >= 10.0:
            self._last_plain = snap.t_s
            self._console.print(table)

    def note(self, line: str) -> None:
        self._console.print(line, markup=False, highlight=False)

    def close(self) -> None:
        if self._live is not None:
            self._live.stop()
            self._live = None
