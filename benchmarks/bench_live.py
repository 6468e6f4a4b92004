"""ehss live over loopback UDP: samples lost, estimator lag and CPU share.

``ehss stream`` sends the simulated rig (position loop, 8 channels at 5 kHz each, 5
samples of 17 float64 fields per datagram: 1000 datagrams/s, 40 000 samples/s) to
``ehss live --udp`` on 127.0.0.1, which identifies all 8 channels (RELS (4,3,0) with
forgetting, evaluation and change detection every 0.1 s) and records everything to HDF5.
The receiver reports its counters, the lag of the estimator behind the newest datagram
(kernel receive time of the datagram → end of its processing; the first poll, which
builds the channels, is reported apart as set-up) and its CPU time from the first
datagram to the last. The recording is compared with the record that was sent.

Runs: the receiver alone (``--quiet``), and with the dashboard server (``--dashboard``,
no browser attached: snapshots with one sliding H1 per snapshot are still built).

Usage::

    python benchmarks/bench_live.py [--duration 10] [--repeat 3]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import select
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

SRC = str(Path(__file__).resolve().parents[1] / "src")
FIELDS8 = ",".join(["t"] + [f"{k}{i}" for i in range(1, 9) for k in ("ref", "fb")])


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait_ready(proc, timeout_s: float = 120.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if select.select([proc.stderr], [], [], 0.5)[0]:
            line = proc.stderr.readline()
            if "ready" in line:
                return
            if not line and proc.poll() is not None:
                break
    raise RuntimeError("ehss live did not start")


def run_once(duration: float, extra: list[str], expected: np.ndarray) -> dict:
    from ehss.live import read_recording

    env = dict(os.environ, PYTHONPATH=SRC + os.pathsep + os.environ.get("PYTHONPATH", ""))
    port = _free_port()
    with tempfile.TemporaryDirectory() as tmp:
        rec, rep = Path(tmp) / "rec.h5", Path(tmp) / "report.json"
        live = subprocess.Popen(
            [sys.executable, "-m", "ehss", "live", "--udp", f"127.0.0.1:{port}", "--fields",
             FIELDS8, "--record", str(rec), "--idle-stop", "3", "--report", str(rep),
             "--quiet", *extra], env=env, stderr=subprocess.PIPE, text=True)
        try:
            _wait_ready(live)
            sent = subprocess.run(
                [sys.executable, "-m", "ehss", "stream", "--rig", "position", "--channels",
                 "8", "--fs", "5000", "--duration", str(duration), "--seed", "2",
                 "--samples-per-packet", "5", "--to", f"127.0.0.1:{port}"],
                env=env, capture_output=True, text=True, timeout=600)
            live.communicate(timeout=120)
        finally:
            live.kill()
            live.stderr.close()
        report = json.loads(rep.read_text())
        samples = read_recording(rec)["samples"]
    report["recording_equal"] = bool(samples.shape == expected.shape
                                     and np.array_equal(samples, expected))
    report["sender"] = sent.stderr.strip().splitlines()[-1]
    return report


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=10.0)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    sys.path.insert(0, SRC)
    from ehss.live import rig_record

    _, expected, _ = rig_record("position", n_channels=8, duration_s=args.duration,
                                fs=5000, seed=2)
    print(f"8 channels × 5 kHz, {args.duration:g} s ({expected.shape[0] * 8} samples), "
          f"5 samples per datagram, {args.repeat} runs each\n")
    print("| run | samples received | lost | lag p50 (ms) | lag p99 (ms) | lag max (ms) "
          "| set-up (ms) | CPU share | recording equal |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---|")
    for name, extra in (("receiver alone", []), ("with dashboard server", ["--dashboard",
                                                                          "0"])):
        for _ in range(args.repeat):
            r = run_once(args.duration, extra, expected)
            c, lag = r["counters"], r["lag_ms"]
            print(f"| {name} | {c['samples']} | {c['lost_samples']} | {lag['p50']:.2f} | "
                  f"{lag['p99']:.2f} | {lag['max']:.1f} | {r['setup_ms']:.0f} | "
                  f"{100 * r['cpu_share']:.1f} % | {'yes' if r['recording_equal'] else 'NO'} |")
    load = os.getloadavg()
    print(f"\n- Machine: {os.cpu_count()} cores, {platform.processor() or platform.machine()}, "
          f"Python {platform.python_version()}; load average during the runs "
          f"{load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} (1/5/15 min).")
    print(f"- Command: `python benchmarks/bench_live.py --duration {args.duration:g} "
          f"--repeat {args.repeat}`")


if __name__ == "__main__":
    main()
