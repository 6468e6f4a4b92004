"""Order search through the identification workflow (ehss.workflow.select_orders)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

from ehss.errors import IdentificationError, ParameterError
from ehss.workflow import Acceptance, identify, select_orders

FS = 200.0


def _record(rng, n=6000, delay=4, noise=0.01):
    """A 2nd-order loop with an input delay of ``delay`` samples, white output noise."""
    u = lfilter([1.0], [1.0, -0.5], rng.standard_normal(n))  # coloured, low-passed test
    b = np.concatenate([np.zeros(delay), [0.05, 0.03]])
    y = 3.0 + lfilter(b, [1.0, -1.5, 0.6], u)
    return u + 1.0, y + noise * np.std(y) * rng.standard_normal(n)


def test_the_pick_refits_to_the_same_fit_and_verdict(rng):
    u, y = _record(rng)
    search = select_orders(u, y, fs=FS, na=[1, 2, 3], nb=[0, 1], nc=[1], delay=[1, 4],
                           decimate=None)
    res = identify(u, y, fs=FS, orders=search.best_orders, decimate=None)
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
    search = select_orders(u, y, fs=FS, na=[2], nb=[1], nc=[1], delay=[4, 5, 8],
                           decimate=4)
    # 4 and 5 record samples are both 1 sample at the decimated rate: one candidate,
    # named by the first record delay that gives it; 8 is 2
    assert search.prepared.decimation == 4
    assert [r.delay for r in search.table] == [1, 2]
    assert search.delays == (4, 8)
    res = identify(u, y, fs=FS, orders=search.best_orders, decimate=4)
    assert res.model.delay == search.best.delay
    assert res.report.simulation_fit_pct == search.best.fit


def test_a_band_ranks_by_the_fit_in_the_band(rng):
    u, y = _record(rng)
    search = select_orders(u, y, fs=FS, na=[1, 2], nb=[1], nc=[1], delay=4,
                           band_hz=(0.0, 20.0), decimate=None)
    reps = search.reports
    assert all(r.band_fit_pct is not None for r in reps)
    assert [r.fit for r in search.table] == [r.band_fit_pct for r in reps]


def test_no_unstable_recommendation(rng):
    # a diverging plant: every least-squares candidate is unstable, none is recommended
    u = rng.standard_normal(600)
    y = lfilter([0.0, 1.0], [1.0, -1.02], u)
    with pytest.raises(IdentificationError, match="none of the 2 candidate orders"):
        select_orders(u, y, fs=1.0, na=[1, 2], nb=[0], nc=[0], delay=1, method="arx",
                      decimate=None)


@pytest.mark.parametrize(
    "kwargs,error,match",
    [
        ({"method": "pem"}, ParameterError, "method='pem' must be one of"),
        ({"initial": "warm"}, ParameterError, "initial='warm' must be 'estimate' or 'zero'"),
        ({"delay": [-1]}, ParameterError, "delay=\\[-1\\] must hold integers >= 0"),
        ({"delay": []}, ParameterError, "must list at least one delay"),
        ({"validation": 1.5}, ParameterError, "validation fraction 1.5 must be in"),
        ({"init": "warm"}, ParameterError, "init='warm' must be one of 'batch', 'zero'"),
        ({"acceptance": 0.9}, TypeError, "acceptance must be an Acceptance"),
    ],
)
def test_bad_settings(rng, kwargs, error, match):
    u, y = _record(rng, n=400)
    args = {"na": [1], "nb": [0], "nc": [0], **kwargs}
    with pytest.raises(error, match=match):
        select_orders(u, y, fs=FS, **args)


def test_the_acceptance_given_is_the_one_judged(rng):
    u, y = _record(rng)
    strict = Acceptance(min_fit_pct=100.0)
    search = select_orders(u, y, fs=FS, na=[2], nb=[1], nc=[1], delay=4, decimate=None,
                           acceptance=strict)
    verdict = search.verdicts[0]
    assert verdict.acceptance is strict and not verdict.accepted
