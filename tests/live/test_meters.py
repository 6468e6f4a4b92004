"""The parts of a live session, each alone: lag and rate meters, the evaluation history."""

from __future__ import annotations

import math

import numpy as np
from numpy.testing import assert_allclose

from ehss.live.meters import Evaluation, EvaluationHistory, LagMeter, RateMeter


def test_lag_meter_percentiles_of_known_lags():
    meter = LagMeter(keep=1000)
    assert math.isnan(meter.stats().p50)
    for ms in range(1, 101):                      # lags of 1..100 ms
        meter.note(1000.0, now_s=1000.0 + ms / 1e3)
    s = meter.stats()
    # the median of 1..100 is 50.5; numpy's linear p99 is 99.01 (float sums: 1e-9)
    assert_allclose([s.p50, s.p99, s.max], [50.5, 99.01, 100.0], rtol=1e-9)
    assert s.to_dict() == {"p50": s.p50, "p99": s.p99, "max": s.max}


def test_lag_meter_keeps_the_latest():
    meter = LagMeter(keep=10)
    for ms in [1000] * 10 + [1] * 10:             # the old large lags are overwritten
        meter.note(0.0, now_s=ms / 1e3)
    assert_allclose(meter.stats().max, 1.0, rtol=1e-12)


def test_rate_meter_over_its_period():
    now = [0.0]
    meter = RateMeter(period_s=1.0, clock=lambda: now[0])
    now[0] = 0.5
    assert meter.update(400) == 0.0               # not a period yet
    now[0] = 2.0
    assert meter.update(1000) == 500.0            # 1000 samples in 2 s
    now[0] = 2.5
    assert meter.update(5000) == 500.0            # held until the next period


def test_history_as_arrays():
    hist = EvaluationHistory(n_params=2, keep=3)
    assert hist.snapshot().t.size == 0
    for i in range(5):
        hist.append(Evaluation(t=0.1 * i, theta=[np.array([i, -i]), None],
                               tracking=np.array([i, 2 * i]), figures=np.full((2, 4), i)))
    h = hist.snapshot()
    assert_allclose(h.t, [0.2, 0.3, 0.4], rtol=1e-12)
    assert h.theta.shape == (3, 2, 2) and np.isnan(h.theta[:, 1]).all()
    assert_allclose(h.theta[:, 0, 1], [-2, -3, -4], rtol=0)
    assert h.tracking.shape == (3, 2) and h.figures.shape == (3, 2, 4)
