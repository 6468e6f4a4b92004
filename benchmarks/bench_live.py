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

``--adaptive``: adaptive compensation instead (:class:`ehss.live.compensate.AdaptiveLoop`
in preview mode, 8 channels at 5 kHz, 0.5–20 Hz references, blocks of 5 ms by default,
the simulated rig as the target), paced to real time: a block arrives when its last
sample is due (the rig's own simulation, the target's work, is not counted against the
host), and the loop waits for it, so that a judgement on a worker has the time between
blocks. Work: the stream's thread's wall time on each block (the estimators fed,
decisions taken up and loads sent, and judgements when they run on that thread), from
the block's arrival or the end of the previous block's work. Lag: from the block's
arrival to the end of its work. Runs with judgements on the stream's thread, on a
worker thread and in a worker process, each with the second estimator (the tracker)
and without it, in the same process.

``--refit``: the wall time of each judgement of adaptive compensation (2 channels of the
rig at 1, 2 and 5 kHz, judged on the stream's thread) with the models refitted to their
output errors and without, in the same process.

Usage::

    python benchmarks/bench_live.py [--duration 10] [--repeat 3] [--adaptive [--block 0.005]]
    python benchmarks/bench_live.py --refit [--duration 10] [--repeat 1]
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


class _TimedTarget:
    """A target that hands its blocks over in real time, and times the loop's work.

    Block k arrives when its last sample is due (stream time from the first block's
    arrival, plus the rig's own simulation time so far: the target's work, not the
    host's); ``step`` waits until then. The loop's work on a block runs from its arrival
    (or the end of the previous block's work, if later) to the next call."""

    def __init__(self, rig) -> None:
        self.rig = rig
        self.arrive_s: list[float] = []
        self.done_s: list[float] = []
        self._start: float | None = None
        self._rig_s = 0.0

    def __getattr__(self, name):
        return getattr(self.rig, name)

    def load(self, channel, compensator, apply_index, crossfade):
        return self.rig.load(channel, compensator, apply_index, crossfade)

    def step(self, n):
        now = time.perf_counter()
        if len(self.done_s) < len(self.arrive_s):
            self.done_s.append(now)
        block = self.rig.step(n)
        self._rig_s += time.perf_counter() - now
        if self._start is None:
            self._start = now
        arrive = self._start + self._rig_s + self.rig.index / self.rig.fs
        wait = arrive - time.perf_counter()
        if wait > 0:
            time.sleep(wait)
        self.arrive_s.append(arrive)
        return block

    def close(self) -> None:
        if len(self.done_s) < len(self.arrive_s):
            self.done_s.append(time.perf_counter())

    def times(self) -> tuple[np.ndarray, np.ndarray]:
        """(work, lag) of each block, s."""
        arrive, done = np.array(self.arrive_s), np.array(self.done_s)
        begin = np.maximum(arrive, np.r_[-np.inf, done[:-1]])
        return done - begin, done - arrive


def run_adaptive(duration: float, tracker: bool, *, fs: float = 5000.0,
                 n_channels: int = 8, block_s: float = 0.005, where: str = "process") -> dict:
    import ehss
    from ehss.compensation.compensator_design import fir_taps
    from ehss.live.compensate import AdaptiveLoop, CompensationSettings
    from ehss.live.rig import SteppingRig

    band = (0.5, 20.0)
    desired = np.vstack([
        ehss.signals.band_limited_random(band_hz=band, rms=5e-4, duration_s=duration,
                                         fs=fs, seed=seed, fade_s=0.2).values
        for seed in range(1, n_channels + 1)])
    # the target reads half the FIR ahead, as `ehss live --compensate preview` has it
    rig = _TimedTarget(SteppingRig("position", desired, fs=fs, preview=fir_taps(fs) // 2,
                                   seed=0))
    settings = CompensationSettings(band_hz=band, judge_in=where,
                                    tracker_trace_bound=1e12 if tracker else None)
    loop = AdaptiveLoop(rig, settings, loop="position", params=ehss.preset("default"))
    rec = loop.run(block_s=block_s)
    rig.close()
    work, lag = rig.times()
    n_block = int(round(block_s * fs))
    return {"blocks": work.size, "samples": int(rec.feedback.shape[1]),
            "expected": desired.shape[1], "work_p50_ms": 1e3 * np.percentile(work, 50),
            "work_p99_ms": 1e3 * np.percentile(work, 99), "work_max_ms": 1e3 * work.max(),
            "real_time_ratio": float(work.sum() / (work.size * block_s)),
            "lag_p99_ms": 1e3 * np.percentile(lag, 99), "lag_max_ms": 1e3 * lag.max(),
            "loads": len(rec.loads), "block_samples": n_block,
            "tracking_um": 1e6 * float(np.sqrt(np.mean(rec.tracking_rms(
                duration / 2, duration) ** 2)))}


def main_adaptive(args) -> None:
    print(f"Adaptive compensation, 8 channels × 5 kHz, {args.duration:g} s paced to real "
          f"time, blocks of {1e3 * args.block:g} ms, {args.repeat} runs each\n")
    print("| judged on | estimators | samples per channel (of) | blocks | work p50 (ms) "
          "| work p99 (ms) | work max (ms) | work / real time | lag p99 (ms) | lag max (ms) "
          "| loads | tracking RMS 2nd half (µm) |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for _ in range(args.repeat):
        for where in ("stream", "thread", "process"):
            for name, tracker in (("one", False), ("two", True)):
                r = run_adaptive(args.duration, tracker, block_s=args.block, where=where)
                print(f"| {where} | {name} | {r['samples']} ({r['expected']}) | "
                      f"{r['blocks']} | {r['work_p50_ms']:.2f} | {r['work_p99_ms']:.1f} | "
                      f"{r['work_max_ms']:.1f} | {r['real_time_ratio']:.3f} | "
                      f"{r['lag_p99_ms']:.1f} | {r['lag_max_ms']:.1f} | {r['loads']} | "
                      f"{r['tracking_um']:.1f} |", flush=True)


def judgement_times(fs: float, refine: bool, duration: float, *, change: bool = False
                    ) -> np.ndarray:
    """Wall time of every judgement (s) of a 2-channel adaptive loop on the rig at ``fs``,
    judged on the stream's thread, with or without the models refitted; with ``change``
    (+40 % payload on channel 1 halfway), only the judgements on rows since a change."""
    import ehss
    from ehss.live import compensate
    from ehss.live.rig import RigEvent, SteppingRig

    band = (0.5, 20.0)
    desired = np.vstack([
        ehss.signals.band_limited_random(band_hz=band, rms=5e-4, duration_s=duration,
                                         fs=fs, seed=seed, fade_s=0.2).values
        for seed in (1, 2)])
    times: list[float] = []
    judge = compensate.Judging.__call__

    def timed(self, t_s, snap):
        t0 = time.perf_counter()
        out = judge(self, t_s, snap)
        if not change or snap.fresh:
            times.append(time.perf_counter() - t0)
        return out

    events = (RigEvent(duration / 2, "load.mass_kg",
                       1.4 * ehss.preset("default").load.mass_kg, "1"),) if change else ()
    compensate.Judging.__call__ = timed
    try:
        rig = SteppingRig("position", desired, fs=fs, preview=128, seed=0, events=events)
        settings = compensate.CompensationSettings(band_hz=band, judge_in="stream",
                                                   refine=refine)
        compensate.AdaptiveLoop(rig, settings, loop="position",
                                params=ehss.preset("default")).run()
    finally:
        compensate.Judging.__call__ = judge
    return np.array(times if change else times[2:])   # the first ones warm the caches


def main_refit(args) -> None:
    print(f"Judgements with and without the models refitted, 2 channels, {args.duration:g} s "
          f"of the rig, {args.repeat} runs each (median and 90th percentile of all)\n")
    print("| rate | without: p50 / p90 (ms) | refitted: p50 / p90 (ms) | refitted / without "
          "(p50) |")
    print("|---:|---:|---:|---:|")
    for fs in (1000.0, 2000.0, 5000.0):
        t = {r: np.concatenate([judgement_times(fs, r, args.duration)
                                for _ in range(args.repeat)]) for r in (False, True)}
        p = {r: (1e3 * np.percentile(v, 50), 1e3 * np.percentile(v, 90))
             for r, v in t.items()}
        print(f"| {fs / 1e3:g} kHz | {p[False][0]:.1f} / {p[False][1]:.1f} | "
              f"{p[True][0]:.1f} / {p[True][1]:.1f} | {p[True][0] / p[False][0]:.2f} |",
              flush=True)
    print("\nAfter +40 % payload on channel 1 halfway: the refitted judgements on rows since "
          "the change (the first refit raced against the first correction, the H1 estimate "
          "of the model's own output), against all refitted ones of the same run\n")
    print("| rate | all: p50 (ms) | since the change: p50 / max (ms) | since / all (p50) |")
    print("|---:|---:|---:|---:|")
    for fs in (1000.0, 2000.0, 5000.0):
        every = np.concatenate([judgement_times(fs, True, args.duration)
                                for _ in range(args.repeat)])
        since = np.concatenate([judgement_times(fs, True, args.duration, change=True)
                                for _ in range(args.repeat)])
        a = 1e3 * np.percentile(every, 50)
        if not since.size:   # no change flagged: nothing judged on rows since one
            print(f"| {fs / 1e3:g} kHz | {a:.1f} | none flagged | |", flush=True)
            continue
        b = 1e3 * np.percentile(since, 50)
        print(f"| {fs / 1e3:g} kHz | {a:.1f} | {b:.1f} / {1e3 * since.max():.1f} | "
              f"{b / a:.2f} |", flush=True)


def _feed_time(kind: str, order: tuple, method: str, u: np.ndarray, y: np.ndarray,
               block: int, fs: float) -> float:
    """Wall time to feed every channel's samples block by block and read every θ̂."""
    import ehss
    from ehss.identification.bank import RelsBank

    na, nb, nc, d = order
    common = dict(na=na, nb=nb, nc=nc, delay=d, method=method, p0=1e6,
                  forgetting=1.0 - 1.0 / (0.3 * fs), dt=1.0 / fs)
    n_ch = u.shape[1]
    if kind == "bank":
        bank = RelsBank(n_channels=n_ch, **common)
        t0 = time.perf_counter()
        for a in range(0, u.shape[0] - block + 1, block):
            bank.update_many(u[a:a + block], y[a:a + block])
            _ = bank.theta
        return time.perf_counter() - t0
    ests = [ehss.RelsEstimator(**common) for _ in range(n_ch)]
    t0 = time.perf_counter()
    for a in range(0, u.shape[0] - block + 1, block):
        for c, e in enumerate(ests):
            e.update_many(u[a:a + block, c], y[a:a + block, c])
        _ = [e.theta for e in ests]
    return time.perf_counter() - t0


def main_bank(args) -> None:
    """Eight channels' estimators fed one by one (RelsEstimator each) against one
    RelsBank, at 5 kHz, for the structures ehss live and its compensation use."""
    fs, n_ch = 5000.0, 8
    n = int(args.duration * fs)
    rng = np.random.default_rng(0)
    u = rng.standard_normal((n, n_ch))
    y = np.zeros_like(u)
    y[1:] = 0.5 * u[:-1] + 0.01 * rng.standard_normal((n - 1, n_ch))
    print(f"8 channels × 5 kHz, {args.duration:g} s of samples; best of {args.repeat}\n")
    print("| structure | block (samples) | one estimator per channel (µs/block) "
          "| RelsBank (µs/block) | bank / separate |")
    print("|---|---:|---:|---:|---:|")
    for order, method in (((4, 3, 4, 1), "rml"), ((6, 5, 6, 1), "rels")):
        for block in (10, 25, 250):
            t = {kind: min(_feed_time(kind, order, method, u, y, block, fs)
                           for _ in range(args.repeat)) for kind in ("separate", "bank")}
            per = {k: 1e6 * v / (n // block) for k, v in t.items()}
            print(f"| {method.upper()} {order} | {block} | {per['separate']:.0f} | "
                  f"{per['bank']:.0f} | {t['bank'] / t['separate']:.2f} |", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=10.0)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--block", type=float, default=0.005,
                    help="--adaptive: block length, s (default 5 ms)")
    ap.add_argument("--adaptive", action="store_true",
                    help="adaptive compensation in process instead of the UDP receiver")
    ap.add_argument("--bank", action="store_true",
                    help="feeding 8 channels: RelsEstimator each against one RelsBank")
    ap.add_argument("--refit", action="store_true",
                    help="adaptive compensation's judgements with and without the refit")
    args = ap.parse_args()
    sys.path.insert(0, SRC)
    if args.refit:
        main_refit(args)
        _machine(args)
        return
    if args.bank:
        main_bank(args)
        _machine(args)
        return
    if args.adaptive:
        main_adaptive(args)
        _machine(args)
        return
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
    _machine(args)


def _machine(args) -> None:
    load = os.getloadavg()
    print(f"\n- Machine: {os.cpu_count()} cores, {platform.processor() or platform.machine()}, "
          f"Python {platform.python_version()}; load average during the runs "
          f"{load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} (1/5/15 min).")
    mode = " --adaptive" if args.adaptive else " --bank" if getattr(args, "bank", False) \
        else " --refit" if getattr(args, "refit", False) else ""
    print(f"- Command: `python benchmarks/bench_live.py --duration {args.duration:g} "
          f"--repeat {args.repeat}{mode}`")


if __name__ == "__main__":
    main()
