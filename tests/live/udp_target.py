"""A real-time target for the loopback tests of adaptive compensation over UDP.

Run as its own process:
``python udp_target.py HOST DATA_PORT DURATION_S SPEED [CHANNELS [CHANGE_S FACTOR]]``.
Its plant is not the simulated rig: on each channel a 12 Hz, ζ = 0.5 second-order
position loop (a mass on the loop's stiffness and damping) behind two samples of delay,
zero-order hold at 1 kHz, with a little white sensor noise. From CHANGE_S on, channel 1
carries FACTOR times its moving mass (ωn and ζ ωn scale by 1/FACTOR^½ and 1/FACTOR:
a heavier payload; the state carried over). It prints the port it takes compensator
datagrams on, then streams ``t, ref<k>, fb<k>, des<k>`` (drive, feedback, desired
reference) in the ``ehss live`` wire format, paced at SPEED × real time, running each
drive through ``ehss.target.CompensatorFilter`` with the reference known PREVIEW samples
ahead and loading every datagram through ``ehss.target.datagram.Inbox``. Alongside, the
same plants run on the desired reference itself (no compensation), and on it through a
second set of filters that loads the datagrams that came before CHANGE_S and none after
(the inverse built before the change, held), for the comparisons. At the end it prints,
as JSON, its counters and each channel's tracking RMS without compensation and with the
held inverse over each second.
"""

from __future__ import annotations

import json
import socket
import sys
import time

import numpy as np
import scipy.signal

from ehss.live.layout import RecordLayout
from ehss.signals import band_limited_random
from ehss.target.datagram import Inbox
from ehss.target.filter import Compensator, CompensatorFilter

FS = 1000.0
PREVIEW = 128
BLOCK = 20
RMS = 1e-3
DELAY = 2


def plant(mass: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(Ad, Bd, C) of the loop with ``mass`` times its moving mass, zero-order hold;
    state (x, ẋ), input the drive DELAY samples before."""
    wn2, c = (2 * np.pi * 12.0) ** 2 / mass, 2 * 0.5 * 2 * np.pi * 12.0 / mass
    a = np.array([[0.0, 1.0], [-wn2, -c]])
    b = np.array([[0.0], [wn2]])
    ad, bd, _, _, _ = scipy.signal.cont2discrete((a, b, np.eye(2), np.zeros((2, 1))),
                                                 1.0 / FS, method="zoh")
    return ad, bd[:, 0], np.array([1.0, 0.0])


class Loop:
    """One channel's loop, stepped sample by sample with its state carried."""

    def __init__(self) -> None:
        self.x = np.zeros(2)
        self.u = np.zeros(DELAY)  # the drive of the last DELAY samples
        self.set_mass(1.0)

    def set_mass(self, mass: float) -> None:
        self.ad, self.bd, self.c = plant(mass)

    def run(self, u: np.ndarray) -> np.ndarray:
        held = np.concatenate([self.u, u])  # held[i] is the drive DELAY samples before i
        y = np.empty(u.size)
        for i in range(u.size):
            y[i] = self.c @ self.x
            self.x = self.ad @ self.x + self.bd * held[i]
        self.u = held[u.size:]
        return y


def main() -> None:
    host, port, duration_s, speed = sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), \
        float(sys.argv[4])
    n_ch = int(sys.argv[5]) if len(sys.argv) > 5 else 1
    change_s, factor = (float(sys.argv[6]), float(sys.argv[7])) if len(sys.argv) > 7 \
        else (np.inf, 1.0)
    n = int(duration_s * FS)
    # a 1 s fade-in: the filter's first PREVIEW drive samples (before any reference
    # reached it) are 0, where the reference is still 4 % of its level at most
    des = np.vstack([band_limited_random(band_hz=(0.5, 20.0), rms=RMS,
                                         duration_s=duration_s, fs=FS, seed=5 + k,
                                         fade_s=1.0).values[:n] for k in range(n_ch)])
    comp_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    comp_sock.bind((host, 0))
    comp_sock.setblocking(False)
    print(comp_sock.getsockname()[1], flush=True)
    out = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    filters = [CompensatorFilter(Compensator.delay(PREVIEW, fs_hz=FS)) for _ in range(n_ch)]
    inbox = Inbox(dict(enumerate(filters)))
    kept = [CompensatorFilter(Compensator.delay(PREVIEW, fs_hz=FS)) for _ in range(n_ch)]
    kept_inbox = Inbox(dict(enumerate(kept)))
    loops, plain, held = ([Loop() for _ in range(n_ch)] for _ in range(3))
    plain_err, held_err = np.empty((n_ch, n)), np.empty((n_ch, n))
    rng = np.random.default_rng(6)
    names = ["t"] + [f"{f}{k + 1}" for k in range(n_ch) for f in ("ref", "fb", "des")]
    layout = RecordLayout(tuple(names))
    sys.stdin.readline()  # the host is ready
    wall0 = time.monotonic()
    changed = False
    for k in range(0, n, BLOCK):
        while True:
            try:
                datagram = comp_sock.recv(65536)
            except BlockingIOError:
                break
            inbox.accept(datagram)
            if k / FS < change_s:
                kept_inbox.accept(datagram)
        m = min(BLOCK, n - k)
        if not changed and k / FS >= change_s:
            for loop in (loops[0], plain[0], held[0]):
                loop.set_mass(factor)
            changed = True
        ahead = np.minimum(np.arange(k, k + m) + PREVIEW, n - 1)
        cols = [np.arange(k, k + m) / FS]
        for c in range(n_ch):
            u = filters[c].process(des[c, ahead])
            noise = 1e-6 * rng.standard_normal(m)
            y = loops[c].run(u) + noise
            plain_err[c, k:k + m] = des[c, k:k + m] - plain[c].run(des[c, k:k + m])
            held_err[c, k:k + m] = des[c, k:k + m] - held[c].run(
                kept[c].process(des[c, ahead])) - noise
            cols += [u, y, des[c, k:k + m]]
        out.sendto(layout.encode(k, np.column_stack(cols)), (host, port))
        lag = (k + m) / FS / speed - (time.monotonic() - wall0)
        if lag > 0:
            time.sleep(lag)
    per_s = int(FS)

    def rms_per_s(err: np.ndarray) -> list:
        return np.sqrt(np.mean(err[:, : n // per_s * per_s].reshape(n_ch, -1, per_s) ** 2,
                               axis=2)).tolist()

    print(json.dumps({"inbox": inbox.counters,
                      "filter": [f.counters for f in filters],
                      "plain_rms_per_s": rms_per_s(plain_err),
                      "held_rms_per_s": rms_per_s(held_err)}), flush=True)


if __name__ == "__main__":
    main()
