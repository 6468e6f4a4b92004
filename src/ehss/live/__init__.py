"""Online identification of a running rig: sources, per-channel estimation, change
detection, recording, dashboard.

``ehss live`` runs a :class:`~ehss.live.session.LiveSession` over a source: a real-time
target's UDP datagrams (:class:`~ehss.live.udp.UdpSource`, format in
:mod:`ehss.live.layout`), the simulated rig (:func:`~ehss.live.rig.rig_record`) or a
recorded file (:func:`~ehss.live.replay.replay_record`), both played to the wall clock
by :class:`~ehss.live.source.PacedSource`. Each channel runs :class:`ehss.RelsEstimator`
with forgetting (:mod:`ehss.live.channel`) and change detection
(:mod:`ehss.live.detect`); the session's other parts (lag and rate meters, sliding H1
estimates, the scheduler of evaluations) are in :mod:`ehss.live.meters`. Everything is
recorded to HDF5 (:mod:`ehss.live.recording`) and shown, from the typed snapshots of
:mod:`ehss.live.snapshot`, in a terminal summary (:mod:`ehss.live.summary`) and a Bokeh
dashboard (:mod:`ehss.live.dashboard`, imported on use), whose compensation panel
shows what :class:`~ehss.live.monitor.CompensationMonitor` gathers while adaptive
compensation (:mod:`ehss.live.compensate`) runs inside the session.
"""

from __future__ import annotations

from ehss.live.channel import ChannelProcessor, EstimatorSettings, reference_band
from ehss.live.detect import FIGURES, DetectionSettings, Detector
from ehss.live.layout import RecordLayout, parse_fields
from ehss.live.monitor import CompensationMonitor
from ehss.live.recording import LiveRecorder, check_new_recording, read_recording
from ehss.live.replay import replay_record
from ehss.live.rig import RigEvent, parse_event, rig_record
from ehss.live.session import LiveReport, LiveSession
from ehss.live.snapshot import (
    ChannelCompensation,
    ChannelSnapshot,
    CompensationSnapshot,
    HistorySnapshot,
    LagStats,
    SessionSnapshot,
)
from ehss.live.source import COUNTERS, Block, PacedSource
from ehss.live.udp import UdpSource, parse_address, stream_record

__all__ = [
    "COUNTERS",
    "FIGURES",
    "Block",
    "ChannelCompensation",
    "ChannelProcessor",
    "ChannelSnapshot",
    "CompensationMonitor",
    "CompensationSnapshot",
    "DetectionSettings",
    "Detector",
    "EstimatorSettings",
    "HistorySnapshot",
    "LagStats",
    "LiveRecorder",
    "LiveReport",
    "LiveSession",
    "PacedSource",
    "RecordLayout",
    "RigEvent",
    "SessionSnapshot",
    "UdpSource",
    "check_new_recording",
    "parse_address",
    "parse_event",
    "parse_fields",
    "read_recording",
    "reference_band",
    "replay_record",
    "rig_record",
    "stream_record",
]
