"""A real-time target for the loopback test of adaptive compensation over UDP.

Run as its own process: ``python udp_target.py HOST DATA_PORT DURATION_S SPEED``. Its
plant is not the simulated rig: a closed loop given as a discrete transfer function (a
12 Hz, ζ = 0.5 second-order loop behind two samples of delay, zero-order hold at
1 kHz) with a little white sensor noise. It prints the port it takes compensator
datagrams on, then streams ``t, ref1, fb1, des1`` (drive, feedback, desired reference)
in the ``ehss live`` wire format, paced at SPEED × real time, running its drive through
``ehss.target.CompensatorFilter`` with the reference known PREVIEW samples ahead and
loading every datagram through ``ehss.target.datagram.Inbox``; at the end it prints its
counters as JSON.
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


def plant() -> tuple[np.ndarray, np.ndarray]:
    wn, zeta = 2 * np.pi * 12.0, 0.5
    b, a, _ = scipy.signal.cont2discrete(([wn * wn], [1.0, 2 * zeta * wn, wn * wn]),
                                         1.0 / FS, method="zoh")
    return np.concatenate([[0.0, 0.0], np.ravel(b)]), np.ravel(a)


def main() -> None:
    host, port, duration_s, speed = sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), \
        float(sys.argv[4])
    n = int(duration_s * FS)
    # a 1 s fade-in: the filter's first PREVIEW drive samples (before any reference
    # reached it) are 0, where the reference is still 4 % of its level at most
    des = band_limited_random(band_hz=(0.5, 20.0), rms=RMS, duration_s=duration_s, fs=FS,
                              seed=5, fade_s=1.0).values[:n]
    comp_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    comp_sock.bind((host, 0))
    comp_sock.setblocking(False)
    print(comp_sock.getsockname()[1], flush=True)
    out = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    filt = CompensatorFilter(Compensator.delay(PREVIEW, fs_hz=FS))
    inbox = Inbox({0: filt})
    b, a = plant()
    zi = np.zeros(max(a.size, b.size) - 1)
    rng = np.random.default_rng(6)
    layout = RecordLayout(("t", "ref1", "fb1", "des1"))
    sys.stdin.readline()  # the host is ready
    wall0 = time.monotonic()
    for k in range(0, n, BLOCK):
        while True:
            try:
                inbox.accept(comp_sock.recv(65536))
            except BlockingIOError:
                break
        m = min(BLOCK, n - k)
        ahead = np.minimum(np.arange(k, k + m) + PREVIEW, n - 1)
        u = filt.process(des[ahead])
        y, zi = scipy.signal.lfilter(b, a, u, zi=zi)
        y = y + 1e-6 * rng.standard_normal(m)
        samples = np.column_stack([np.arange(k, k + m) / FS, u, y, des[k:k + m]])
        out.sendto(layout.encode(k, samples), (host, port))
        lag = (k + m) / FS / speed - (time.monotonic() - wall0)
        if lag > 0:
            time.sleep(lag)
    print(json.dumps({"inbox": inbox.counters, "filter": filt.counters}), flush=True)


if __name__ == "__main__":
    main()
