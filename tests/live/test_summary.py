"""The terminal summary shows each channel's state and the packet counters."""

from __future__ import annotations

import io
import json
import math
import pickle

from ehss.live import DetectionSettings, EstimatorSettings, LiveSession, PacedSource, rig_record
from ehss.live.snapshot import SessionSnapshot
from ehss.live.summary import TerminalSummary


def test_summary_lists_channels_and_counters():
    layout, x, fs = rig_record("position", n_channels=2, duration_s=3.0, seed=1)
    session = LiveSession(PacedSource(layout, x, fs, speed=math.inf),
                          est=EstimatorSettings(), det=DetectionSettings(learn_s=1.0))
    report = session.run()
    snap = session.snapshot()
    # a frozen snapshot, read by attribute, that pickles (to the dashboard's process)
    # and has a JSON form
    assert isinstance(snap, SessionSnapshot) and snap.samples == report.samples == 3000
    assert [ch.name for ch in snap.channels] == ["1", "2"]
    assert snap.history.theta.shape[1:] == (2, EstimatorSettings().n_params)
    assert pickle.loads(pickle.dumps(snap)).t_s == snap.t_s
    json.dumps(snap.to_dict())
    json.dumps(report.to_dict())
    out = io.StringIO()
    summary = TerminalSummary(out)       # not a terminal: plain tables
    summary.update(snap)
    summary.note("an alarm line")
    summary.close()
    text = out.getvalue()
    assert "packets" in text and "lost 0" in text and "an alarm line" in text
    for word in ("ch", "FRF", "ok"):
        assert word in text
