"""Adaptive compensation over UDP on loopback, with a target in its own process whose
plant is not the simulated rig."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from ehss.live.compensate import (
    AdaptiveLoop,
    CompensationSettings,
    DatagramSender,
    UdpTarget,
)
from ehss.live.layout import RecordLayout
from ehss.live.udp import UdpSource

TARGET = Path(__file__).with_name("udp_target.py")
SRC = Path(__file__).resolve().parents[2] / "src"


@pytest.mark.slow
@pytest.mark.realtime
def test_a_remote_target_takes_the_compensators():
    layout = RecordLayout(("t", "ref1", "fb1", "des1"))
    source = UdpSource(layout, ("127.0.0.1", 0), fs=1000.0)
    env = {"PYTHONPATH": str(SRC)}
    proc = subprocess.Popen(
        [sys.executable, str(TARGET), "127.0.0.1", str(source.address[1]), "12", "1"],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env)
    sender = None
    try:
        comp_port = int(proc.stdout.readline())
        sender = DatagramSender(("127.0.0.1", comp_port), first_sequence=1)
        target = UdpTarget(source, sender, fs=1000.0, preview=128, reference_rms=[1e-3],
                           idle_stop_s=1.0)
        settings = CompensationSettings(band_hz=(0.5, 20.0), na=4, nb=3, nc=4)
        loop = AdaptiveLoop(target, settings)
        proc.stdin.write("go\n")
        proc.stdin.flush()
        rec = loop.run()
        counters = json.loads(proc.stdout.readline())
        proc.wait(timeout=30)
    finally:
        proc.kill()
        proc.wait(timeout=30)
        proc.stdin.close()
        proc.stdout.close()
        source.close()
        if sender is not None:
            sender.close()
    n = rec.desired.shape[1]
    assert n == 12_000  # every sample came, in order, on loopback
    # before the first compensator is in (2 s and its settling) the loop runs plain: a
    # 12 Hz loop lags its 0.5-20 Hz reference by tens of degrees
    before = rec.tracking_rms(1.0, 2.0)[0]
    after = rec.tracking_rms(7.0, 12.0)[0]
    assert after <= before / 20.0
    # every datagram loaded but perhaps the last, sent after the target's last sample;
    # none refused
    inbox = counters["inbox"]
    assert sender.sent - 1 <= inbox["ok"] <= sender.sent and inbox["ok"] > 0
    assert sum(inbox.values()) == inbox["ok"]
    assert counters["filter"]["swaps"] > 0
