"""Adaptive compensation over UDP on loopback, with a target in its own process whose
plant is not the simulated rig (``udp_target.py``: a 12 Hz, ζ = 0.5 position loop
behind two samples of delay on each of two channels), and a +40 % payload on channel 1
while it runs."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from ehss.live.compensate import (
    AdaptiveLoop,
    CompensationSettings,
    DatagramSender,
    UdpTarget,
)
from ehss.live.layout import RecordLayout
from ehss.live.source import Block
from ehss.live.udp import UdpSource

TARGET = Path(__file__).with_name("udp_target.py")
SRC = Path(__file__).resolve().parents[2] / "src"
FS = 1000.0
DURATION_S = 22.0
CHANGE_S = 14.0
FIELDS = ("t", *(f"{f}{k}" for k in (1, 2) for f in ("ref", "fb", "des")))


class _Arrived:
    """A source whose blocks arrived at given wall-clock times."""

    def __init__(self, blocks: list[Block]) -> None:
        self.layout = RecordLayout(("t", "ref1", "fb1", "des1"))
        self.blocks, self.finished = blocks, False

    def poll(self, timeout_s: float) -> list[Block]:
        out, self.blocks = self.blocks, []
        return out


@pytest.mark.parametrize("rate", [1000.0, 4000.0])
def test_the_target_is_placed_by_its_own_clock(rate):
    # blocks of 20 samples that a target running at `rate` samples a second sent over
    # the last 2 s, the latest 0.1 s ago: it is now 0.1 s of samples past them, and at
    # most one block more; the host's own sample rate does not enter
    now = time.time()
    n, block = int(2.0 * rate), 20
    blocks = [Block(k, np.zeros((block, 4)), now - 0.1 - (n - k - block) / rate)
              for k in range(0, n, block)]
    target = UdpTarget(_Arrived(blocks), None, fs=1000.0, preview=0, reference_rms=[1.0])
    assert target.ahead() == 0   # nothing came yet: nothing to place it by
    target.step(n - 2 * block)   # the host takes what came
    assert target.index == n
    expected = 0.1 * rate + block
    assert expected <= target.ahead() <= expected + 0.01 * rate   # 10 ms for this test


class _Sent:
    def send(self, channel, compensator, apply_index, crossfade):
        return True


class _OneByOne(_Arrived):
    """A source whose blocks come one per poll."""

    def poll(self, timeout_s: float) -> list[Block]:
        return [self.blocks.pop(0)] if self.blocks else []


@pytest.mark.parametrize("runs", [False, True, "off", "late", "lone"])
def test_a_target_that_runs_no_compensator_is_told(runs):
    # a target refuses every compensator whose preview is not its own, and its drive
    # stays its desired reference (the compensator it starts with): the host says so,
    # once, when the second one sent should have been running for IGNORED_AFTER_S
    # (IGNORED_LONE_S after the first when it was the only one); a target that took the
    # first one up too late for it to show by then ("late": a host or target that lost
    # the processor for a while) and ran the second, or one sent a compensator that
    # passes the reference (compensation switched off), tells nothing
    from ehss.live.compensate.udp_target import IGNORED_AFTER_S, IGNORED_LONE_S
    from ehss.target import Compensator

    fir = Compensator(sos=np.zeros((0, 6)), taps=np.r_[np.zeros(128), 0.9, 0.1],
                      preview=128, fs_hz=1000.0)
    first = Compensator.delay(128, fs_hz=1000.0) if runs == "off" else fir

    fs, n = 1000.0, 50
    des = np.sin(np.arange(4000) / 30.0)
    drive = 1.01 * des if runs is True else des.copy()
    if runs == "late":
        drive[1000:] *= 1.01      # the first never showed, the second from its apply index
    blocks = [Block(k, np.column_stack([np.arange(k, k + n) / fs, drive[k:k + n],
                                        np.zeros(n), des[k:k + n]]), 0.0)
              for k in range(0, des.size, n)]
    told = []
    target = UdpTarget(_OneByOne(blocks), _Sent(), fs=fs, preview=128, reference_rms=[1.0],
                       warn=told.append)
    target.load(0, first, apply_index=200, crossfade=100)
    target.step(250)
    if runs != "lone":
        target.load(0, fir, apply_index=1000, crossfade=100)
    due = 1100 + IGNORED_AFTER_S * fs if runs != "lone" else 300 + IGNORED_LONE_S * fs
    target.step(int(due) - 250 - n)                # up to the block that reaches past it
    assert target.index == due - n and not told and not target.ignored
    target.load(0, fir, apply_index=2500, crossfade=100)   # later ones change nothing
    target.step(4000 - target.index)
    if runs in (True, "off", "late"):
        assert not told and not target.ignored
    else:
        assert len(told) == 1 and target.ignored == {0: told[0]}
        after = f"{IGNORED_AFTER_S:g} s after the second" if runs is False \
            else f"{IGNORED_LONE_S:g} s after the first"
        assert "128 samples ahead at 1000 Hz" in told[0] and after in told[0], told[0]


def _run(speed: float, **settings):
    """One run against a fresh target process paced at ``speed`` × real time: the
    host's record, the target's counters and the sender's count."""
    source = UdpSource(RecordLayout(FIELDS), ("127.0.0.1", 0), fs=FS)
    proc = subprocess.Popen(
        [sys.executable, str(TARGET), "127.0.0.1", str(source.address[1]),
         str(DURATION_S), str(speed), "2", str(CHANGE_S), "1.4"],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
        env={"PYTHONPATH": str(SRC)})
    sender = None
    try:
        comp_port = int(proc.stdout.readline())
        sender = DatagramSender(("127.0.0.1", comp_port), first_sequence=1)
        target = UdpTarget(source, sender, fs=FS, preview=128,
                           reference_rms=[1e-3, 1e-3], idle_stop_s=1.0)
        loop = AdaptiveLoop(target, CompensationSettings(band_hz=(0.5, 20.0), **settings))
        proc.stdin.write("go\n")
        proc.stdin.flush()
        rec = loop.run()
        counters = json.loads(proc.stdout.readline())
        # the target ran what it was sent: the host did not take it for one that refuses
        assert not target.ignored, (target.ignored, counters["inbox"], counters["filter"],
                                    [(e["channel"], e["t_s"], e["apply_index"])
                                     for e in loop.loads][:6])
        proc.wait(timeout=30)
    finally:
        proc.kill()
        proc.wait(timeout=30)
        proc.stdin.close()
        proc.stdout.close()
        source.close()
        if sender is not None:
            sender.close()
    return rec, counters, sender.sent


def _course(rec) -> list[tuple]:
    """What channel 1 was sent, refused and flagged from the change on: the reading of
    a failure."""
    return [(e["t_s"], e["kind"], e.get("model"), e.get("apply_index"), e.get("reason"))
            for e in rec.events if e.get("channel") == "1" and e["t_s"] >= CHANGE_S]


@pytest.mark.slow
@pytest.mark.realtime
def test_a_remote_target_follows_a_payload_change():
    # paced at real time, as a target runs: the host's latency (the worker's judgement,
    # the datagram, the target's inbox), tens of milliseconds, puts each load that many
    # samples times the pace later in the stream; at 8x a load judged 1 s after the
    # change came in 0.9-1.3 s later, at 1x and 2x 0.45-0.5 s later, as in process, but
    # at 2x a host whose cores were taken by other work came 2 s after the change at
    # 1.5-4.8x its level before. Alongside, the target runs the same plants through
    # filters that took the compensators that came before the change and none after:
    # the inverse built before the change, held
    rec, counters, sent = _run(1.0)
    assert rec.desired.shape == (2, int(DURATION_S * FS))  # every sample, in order
    before = rec.tracking_rms(8.0, CHANGE_S)
    # the loop lags its 0.5-20 Hz reference by tens of degrees: compensated, its error
    # is at least 20 times less (the target runs the same plants uncompensated alongside)
    plain = np.sqrt(np.mean(np.square(counters["plain_rms_per_s"])[:, 8:int(CHANGE_S)],
                            axis=1))
    assert np.all(before <= plain / 20.0)
    # the change is flagged on channel 1 within 1.5 s, and channel 2 never
    changes = [(e["channel"], e["t_s"]) for e in rec.events
               if e["kind"] == "compensator_change"]
    assert changes and changes[0][0] == "1" and CHANGE_S < changes[0][1] <= CHANGE_S + 1.5
    assert all(ch == "1" for ch, _ in changes)
    # +40 % mass raises this loop's error under the old inverse about 70-fold (the rig's:
    # 9-fold); the first model refitted on the rows since the change (1 s of them) is
    # in 1.5 s after it. From 2 s after the change every 2-s stretch of channel 1 is
    # within 1.5x its level before (1.15-1.33x over [16, 18) s, at most 1.24x later:
    # three runs; README, "A real target over UDP")
    stretches = [(a, a + 2.0) for a in np.arange(CHANGE_S + 2.0, DURATION_S, 2.0)]
    for w in stretches:
        assert rec.tracking_rms(*w)[0] <= 1.5 * before[0], (w, _course(rec))
    # while the inverse built before the change stays at least 2x worse there (its
    # RMS over each second, from the target)
    held = np.asarray(counters["held_rms_per_s"])
    for a, b in stretches:
        frozen = np.sqrt(np.mean(held[0, int(a):int(b)] ** 2))
        assert frozen >= 2.0 * rec.tracking_rms(a, b)[0], ((a, b), frozen)
    # and up to the change it ran what the adapted one ran, on the same samples with the
    # same sensor noise: the same error over the last whole second before it, to rounding
    ran = rec.tracking_rms(CHANGE_S - 1.0, CHANGE_S)
    np.testing.assert_allclose(held[:, int(CHANGE_S) - 1], ran, rtol=1e-9)
    # channel 2 does not change (the rig's bound: the scatter of 1-s stretches, +-30 %)
    assert rec.tracking_rms(CHANGE_S + 2.0, DURATION_S)[1] <= 1.3 * before[1]
    assert not [e for e in rec.events if e["kind"] == "alarm"]
    # every datagram loaded but perhaps the last, sent after the target's last sample;
    # none refused; both channels swapped compensators
    inbox = counters["inbox"]
    assert sent - 1 <= inbox["ok"] <= sent and inbox["ok"] > 0
    assert sum(inbox.values()) == inbox["ok"]
    assert all(f["swaps"] > 0 for f in counters["filter"])
