"""Cost of live change detection per update: ``ChannelProcessor.feed`` on 10 samples
(2 ms at 5 kHz, what ``ehss live`` gathers per update), with and without the
baseline's prediction-error filter of the sequential test, in one process.

    python benchmarks/bench_detect.py [--repeat 3]
"""

from __future__ import annotations

import argparse
import time

from ehss.live import DetectionSettings, EstimatorSettings, rig_record
from ehss.live.channel import ChannelProcessor

FS = 5000.0
LEARN_S = 10.0


def per_feed_us(u, y, *, with_test: bool) -> float:
    """Mean wall time of one feed of 10 samples after the learning time, µs."""
    p = ChannelProcessor("1", FS, EstimatorSettings(), DetectionSettings(learn_s=LEARN_S))
    n_learn, step = int(LEARN_S * FS), 500
    for k in range(0, n_learn + step, step):
        p.feed(u[k:k + step], y[k:k + step])
        p.evaluate(k / FS, p.capture())
    if p.residual is None:
        raise RuntimeError("the test did not start")
    if not with_test:
        p.residual = None
    t0, n = time.perf_counter(), 0
    for k in range(n_learn + step, u.size - 10, 10):
        p.feed(u[k:k + 10], y[k:k + 10])
        n += 1
    return (time.perf_counter() - t0) / n * 1e6


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    _, x, _ = rig_record("position", n_channels=1, duration_s=14.0, seed=1, fs=FS)
    u, y = x[:, 1].copy(), x[:, 2].copy()
    for _ in range(args.repeat):
        a = per_feed_us(u, y, with_test=False)
        b = per_feed_us(u, y, with_test=True)
        print(f"feed of 10 samples: estimator {a:.1f} µs, with the test {b:.1f} µs, "
              f"ratio {b / a:.2f}")


if __name__ == "__main__":
    main()
