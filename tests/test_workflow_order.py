"""Order search through the identification workflow (ehss.workflow.select_orders)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

from ehss.errors import IdentificationError, ParameterError
from ehss.workflow import (
    Acceptance,
    Estimation,
    Evaluation,
    OrderGrid,
    Preparation,
    identify,
    select_orders,
)

FS = 200.0


def _record(rng, n=6000, delay=4, noise=0.01):
    """A 2nd-order loop with an input delay of ``delay`` samples, white output noise."""
    u = lfilter([1.0], [1.0, -0.5], rng.standard_normal(n))  # coloured, low-passed test
    b = np.concatenate([np.zeros(delay), [0.05, 0.03]])
    y = 3.0 + lfilter(b, [1.0, -1.5, 0.6], u)
    return u + 1.0, y + noise * np.std(y) * rng.standard_normal(n)


def test_the_pick_refits_to_the_same_fit_and_verdict(rng):
    u, y = _record(rng)
    search = select_orders(u, y, fs=FS,
                           grid=OrderGrid(na=[1, 2, 3], nb=[0, 1], nc=[1], delay=[1, 4]),
                           preparation=Preparation(decimate=None))
    res = identify(u, y, fs=FS, orders=search.best_orders,
                   preparation=Preparation(decimate=None))
    # same prepared data, deterministic estimator, same validation: identical numbers
    assert res.report.simulation_fit_pct == search.best.fit
    assert res.verdict.accepted == search.verdicts[search.best_index].accepted
    assert search.best_orders[0] == 2 and search.best_orders[3] == 4
    assert res.model.is_stable() and search.best.stable
    # a row's columns come from its own validation
    for row, rep in zip(search.table, search.reports, strict=True):
        assert rep is not None and row.fit == rep.fit_pct


def test_delays_are_in_record_samples_and_follow_the_decimation(rng):
    u, y = _record(rng, n=8000, delay=4)
    search = select_orders(u, y, fs=FS,
                           grid=OrderGrid(na=[2], nb=[1], nc=[1], delay=[4, 5, 8]),
                           preparation=Preparation(decimate=4))
    # 4 and 5 record samples are both 1 sample at the decimated rate: one candidate,
    # named by the first record delay that gives it; 8 is 2
    assert search.prepared.decimation == 4
    assert [r.delay for r in search.table] == [1, 2]
    assert search.delays == (4, 8)
    res = identify(u, y, fs=FS, orders=search.best_orders,
                   preparation=Preparation(decimate=4))
    assert res.model.delay == search.best.delay
    assert res.report.simulation_fit_pct == search.best.fit


def test_a_band_ranks_by_the_fit_in_the_band(rng):
    u, y = _record(rng)
    search = select_orders(u, y, fs=FS, grid=OrderGrid(na=[1, 2], nb=[1], nc=[1], delay=4),
                           preparation=Preparation(band_hz=(0.0, 20.0), decimate=None))
    reps = search.reports
    assert all(r.band_fit_pct is not None for r in reps)
    assert [r.fit for r in search.table] == [r.band_fit_pct for r in reps]


def test_no_unstable_recommendation(rng):
    # a diverging plant: every least-squares candidate is unstable, none is recommended
    u = rng.standard_normal(600)
    y = lfilter([0.0, 1.0], [1.0, -1.02], u)
    with pytest.raises(IdentificationError, match="none of the 2 candidate orders"):
        select_orders(u, y, fs=1.0, grid=OrderGrid(na=[1, 2], nb=[0], nc=[0], delay=1),
                      preparation=Preparation(decimate=None),
                      estimation=Estimation(method="arx"))


@pytest.mark.parametrize(
    "make,error,match",
    [
        (lambda: {"estimation": Estimation(method="pem")}, ParameterError,
         "method='pem' must be one of"),
        (lambda: {"evaluation": Evaluation(initial="warm")}, ParameterError,
         "initial='warm' must be one of 'estimate', 'zero'"),
        (lambda: {"grid": OrderGrid(na=[1], delay=[-1])}, ParameterError,
         "delay=\\[-1\\] must hold integers >= 0"),
        (lambda: {"grid": OrderGrid(na=[1], delay=[])}, ParameterError,
         "must list at least one delay"),
        (lambda: {"grid": OrderGrid(criterion="bic")}, ParameterError,
         "criterion='bic' must be one of"),
        (lambda: {"grid": OrderGrid(error_tolerance=-0.1)}, ParameterError,
         "error_tolerance=-0.1"),
        (lambda: {"preparation": Preparation(validation=1.5)}, ParameterError,
         "validation=1.5 must be in"),
        (lambda: {"estimation": Estimation(init="warm")}, ParameterError,
         "init='warm' must be one of 'batch', 'zero'"),
        (lambda: {"acceptance": 0.9}, TypeError, "acceptance must be an Acceptance"),
        (lambda: {"grid": [1, 2]}, TypeError, "grid must be an OrderGrid"),
    ],
)
def test_bad_settings(rng, make, error, match):
    u, y = _record(rng, n=400)
    with pytest.raises(error, match=match):
        select_orders(u, y, fs=FS, **{"grid": OrderGrid(na=[1], nb=[0], nc=[0]), **make()})


def test_the_acceptance_given_is_the_one_judged(rng):
    u, y = _record(rng)
    strict = Acceptance(min_fit_pct=100.0)
    search = select_orders(u, y, fs=FS, grid=OrderGrid(na=[2], nb=[1], nc=[1], delay=4),
                           preparation=Preparation(decimate=None), acceptance=strict)
    verdict = search.verdicts[0]
    assert verdict.acceptance is strict and not verdict.accepted
