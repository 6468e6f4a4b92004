"""Cost of live change detection per update: ``ChannelProcessor.feed`` on 10 samples
(2 ms at 5 kHz, what ``ehss live`` gathers per update), with the estimator alone, with
the sequential test's first predictor (the baseline's prediction errors) and with both
(and the output errors of its refitted B/A), in one process; and the refit of the
second predictor, once per channel, off the stream's thread.

    python benchmarks/bench_detect.py [--repeat 3]
"""

from __future__ import annotations

import argparse
import time

from ehss.live import DetectionSettings, EstimatorSettings, rig_record
from ehss.live.channel import ChannelProcessor
from ehss.live.detect import output_error_predictor

FS = 5000.0
LEARN_S = 10.0


def per_feed_us(u, y, *, predictors: int) -> float:
    """Mean wall time of one feed of 10 samples once both predictors of the test run,
    with the first ``predictors`` of them kept (0: none), µs."""
    p = ChannelProcessor("1", FS, EstimatorSettings(), DetectionSettings(learn_s=LEARN_S))
    step, k = 500, 0
    while len(p.residuals) < 2:
        if k + step > u.size:
            raise RuntimeError("the test did not start with both predictors")
        p.feed(u[k:k + step], y[k:k + step])
        p.evaluate(k / FS, p.capture())
        k += step
    p.residuals = p.residuals[:predictors]
    t0, n = time.perf_counter(), 0
    for j in range(k, u.size - 10, 10):
        p.feed(u[j:j + 10], y[j:j + 10])
        n += 1
    return (time.perf_counter() - t0) / n * 1e6


def refit_ms(u, y) -> float:
    """Wall time of the second predictor's refit on the learning time's last three
    quarters (off the stream's thread in ``ehss live``), ms."""
    p = ChannelProcessor("1", FS, EstimatorSettings(), DetectionSettings(learn_s=LEARN_S))
    n_learn, step = int(LEARN_S * FS), 500
    for k in range(0, n_learn + step, step):
        p.feed(u[k:k + step], y[k:k + step])
        p.evaluate(k / FS, p.capture())
    model = p.baseline
    t0 = time.perf_counter()
    output_error_predictor(model, u[n_learn // 4:n_learn], y[n_learn // 4:n_learn])
    return (time.perf_counter() - t0) * 1e3


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    _, x, _ = rig_record("position", n_channels=1, duration_s=16.0, seed=1, fs=FS)
    u, y = x[:, 1].copy(), x[:, 2].copy()
    for _ in range(args.repeat):
        a = per_feed_us(u, y, predictors=0)
        b = per_feed_us(u, y, predictors=1)
        c = per_feed_us(u, y, predictors=2)
        print(f"feed of 10 samples: estimator {a:.1f} µs, with the first predictor "
              f"{b:.1f} µs (ratio {b / a:.2f}), with both {c:.1f} µs (ratio {c / a:.2f}); "
              f"refit of the second {refit_ms(u, y):.0f} ms", flush=True)


if __name__ == "__main__":
    main()
