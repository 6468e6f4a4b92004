"""The terminal summary shows each channel's state and the packet counters."""

from __future__ import annotations

import io
import math

from ehss.live import DetectionSettings, EstimatorSettings, LiveSession, PacedSource, rig_record
from ehss.live.summary import TerminalSummary


def test_summary_lists_channels_and_counters():
    layout, x, fs = rig_record("position", n_channels=2, duration_s=3.0, seed=1)
    session = LiveSession(PacedSource(layout, x, fs, speed=math.inf),
                          est=EstimatorSettings(), det=DetectionSettings(learn_s=1.0))
    session.run()
    out = io.StringIO()
    summary = TerminalSummary(out)       # not a terminal: plain tables
    summary.update(session.snapshot())
    summary.note("an alarm line")
    summary.close()
    text = out.getvalue()
    assert "packets" in text and "lost 0" in text and "an alarm line" in text
    for word in ("ch", "FRF", "ok"):
        assert word in text
