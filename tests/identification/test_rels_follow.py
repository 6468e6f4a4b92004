"""RelsEstimator's bound of tr P and its P changed while it runs (following a change)."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from ehss.errors import DataError, ParameterError
from ehss.identification.rels import RelsEstimator

from .systems import armax_data, system

#: the diagonal floor added to P after each update with λ < 1 (identification/_kernels)
_EPS_FLOOR = 8.0 * np.finfo(float).eps


def _estimator(**kw):
    return RelsEstimator(na=2, nb=1, nc=1, delay=1, forgetting=0.99, p0=1e3, **kw)


def test_a_lifted_bound_lets_the_forgetting_act():
    # u = y = 0: ψ̂ = 0, so (22) is P(k) = P(k−1)/λ, plus the floor δ = 8 n eps tr P on
    # the diagonal: tr P grows by (1 + 8 n² eps)/λ a sample, exactly
    n_params, lam, n = 5, 0.99, 200
    held = _estimator()
    held.update_many(np.zeros(n), np.zeros(n))
    tr0 = n_params * 1e3
    # held at tr P(0), its default bound, from the first sample
    assert held.trace_bound == tr0
    assert np.trace(held.P) == pytest.approx(tr0, rel=1e-12)
    lifted = _estimator()
    lifted.set_trace_bound(1e12)
    assert lifted.trace_bound == 1e12
    lifted.update_many(np.zeros(n), np.zeros(n))
    growth = ((1.0 + _EPS_FLOOR * n_params**2) / lam) ** n
    # n roundings of one multiply-add each: 1e-12 is ample
    assert np.trace(lifted.P) == pytest.approx(tr0 * growth, rel=1e-12)
    # brought back down, P is scaled to the bound at once
    lifted.set_trace_bound(None)
    assert lifted.trace_bound == tr0
    assert np.trace(lifted.P) == pytest.approx(tr0, rel=1e-12)


def test_the_covariance_set_back_runs_on_as_if_untouched(rng):
    a, b, c = system(2)
    u, y, _ = armax_data(rng, a, b, c, 3000, snr_db=30.0)
    ref, est = _estimator(), _estimator()
    ref.update_many(u, y)
    est.update_many(u[:1500], y[:1500])
    P = est.P
    est.set_trace_bound(1e12)
    est.set_trace_bound(None)
    est.set_covariance(P)
    assert_allclose(est.P, P, rtol=0, atol=0)
    est.update_many(u[1500:], y[1500:])
    # the pending (22) applied apart from the next gain: the same operations but for
    # the rounding of g = P r formed after P instead of beside it
    assert_allclose(est.theta, ref.theta, rtol=1e-9)


def test_a_covariance_beyond_the_bound_is_scaled_to_it():
    est = _estimator()
    est.set_covariance(np.diag([1e4, 2e4, 3e4, 4e4, 5e4]))
    assert np.trace(est.P) == pytest.approx(5e3, rel=1e-12)
    assert_allclose(np.diag(est.P), np.array([1.0, 2.0, 3.0, 4.0, 5.0]) * 5e3 / 15,
                    rtol=1e-12)


@pytest.mark.parametrize(("P", "message"), [
    (np.eye(4), "shape"),
    (np.full((5, 5), np.nan), "finite"),
    (np.eye(5) + np.triu(np.ones((5, 5)), 1), "symmetric"),
    (-np.eye(5), "positive definite"),
])
def test_a_bad_covariance_is_refused_and_nothing_changes(P, message):
    est = _estimator()
    before = est.P
    with pytest.raises(DataError, match=message):
        est.set_covariance(P)
    assert_allclose(est.P, before, rtol=0, atol=0)


@pytest.mark.parametrize(("bound", "error"), [(0.0, ParameterError), (-1.0, ParameterError),
                                              ("big", TypeError)])
def test_a_bad_bound_is_refused_and_nothing_changes(bound, error):
    est = _estimator()
    with pytest.raises(error, match="trace_bound"):
        est.set_trace_bound(bound)
    assert est.trace_bound == 5e3
