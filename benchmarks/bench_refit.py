"""Cost of the models' refits in adaptive compensation: the wall time of
``Judging.refine`` and of the judgements that refit, on 2 channels of the simulated rig's
position loop for 10 s, ``refine=True``, judged on the stream's thread, at 1, 2 and
5 kHz. Run it on two trees (``PYTHONPATH=<tree>/src``), alternated, to compare them.

    python benchmarks/bench_refit.py [--duration 10]
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

import ehss
from ehss.live import compensate
from ehss.live.compensate import judging
from ehss.live.rig import SteppingRig

BAND = (0.5, 20.0)


def refit_times(fs: float, duration: float) -> tuple[np.ndarray, np.ndarray]:
    """Wall times (ms) of every refit and of every judgement that refitted, the first
    two of each left out (they warm the caches)."""
    desired = np.vstack([
        ehss.signals.band_limited_random(band_hz=BAND, rms=5e-4, duration_s=duration,
                                         fs=fs, seed=seed, fade_s=0.2).values
        for seed in (1, 2)])
    refits: list[float] = []
    judgements: list[float] = []
    refine, judge = judging.Judging.refine, judging.Judging.__call__

    def timed_refine(self, *args, **kwargs):
        t0 = time.perf_counter()
        out = refine(self, *args, **kwargs)
        refits.append(time.perf_counter() - t0)
        return out

    def timed_judge(self, *args, **kwargs):
        n = len(refits)
        t0 = time.perf_counter()
        out = judge(self, *args, **kwargs)
        if len(refits) > n:
            judgements.append(time.perf_counter() - t0)
        return out

    judging.Judging.refine, judging.Judging.__call__ = timed_refine, timed_judge
    try:
        rig = SteppingRig("position", desired, fs=fs, preview=128, seed=0)
        settings = compensate.CompensationSettings(band_hz=BAND, judge_in="stream",
                                                   refine=True)
        compensate.AdaptiveLoop(rig, settings, loop="position",
                                params=ehss.preset("default")).run()
    finally:
        judging.Judging.refine, judging.Judging.__call__ = refine, judge
    return 1e3 * np.array(refits[2:]), 1e3 * np.array(judgements[2:])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=10.0)
    args = ap.parse_args()
    print(f"ehss from {os.path.dirname(ehss.__file__)}")
    print("| rate | refits | refit p50 / p90 (ms) | judgement that refits p50 / p90 (ms) |")
    print("|---:|---:|---:|---:|")
    for fs in (1000.0, 2000.0, 5000.0):
        r, j = refit_times(fs, args.duration)
        print(f"| {fs / 1e3:g} kHz | {r.size} | {np.median(r):.1f} / {np.percentile(r, 90):.1f}"
              f" | {np.median(j):.1f} / {np.percentile(j, 90):.1f} |", flush=True)
    load = os.getloadavg()
    print(f"- load average {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} (1/5/15 min)")


if __name__ == "__main__":
    main()
