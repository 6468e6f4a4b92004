"""Hypothesis invariants of the RELS estimator: P stays SPD and bounded, no NaN out."""

from __future__ import annotations

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ehss.identification import _kernels as K
from ehss.identification._common import new_state
from ehss.identification.rels import RelsEstimator

from .systems import armax_data, kernel_settings, system


def _block(block, u, y, n):
    rec = K.record(u, y)
    assert K.rels_run(block, rec, np.empty((0, n)), 1, True) == u.size
    return rec[2], rec[3]


@settings(max_examples=5, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(level=st.floats(-1e3, 1e3), seed=st.integers(0, 2**32 - 1))
def test_p_spd_and_bounded_through_a_million_samples_of_constant_input(level, seed):
    rng = np.random.default_rng(seed)
    na, nb, nc, n = 2, 1, 1, 5
    alpha = 1e3
    settings = kernel_settings(na, nb, nc, 1, 0.99, alpha, alpha, n * alpha, 0.99, "rels")
    state, views = new_state(settings, np.zeros(n))
    a, b, c = system(2)
    u, y, _ = armax_data(rng, a, b, c, 4000, snr_db=40.0)
    _block(state, u, y, n)
    theta_good = views.theta.copy()
    # 10^6 samples of constant input/output, checked every 10^5 samples
    cu = np.full(100_000, level)
    for _ in range(10):
        err, xi = _block(state, cu, cu * 0.5, n)
        assert np.all(np.isfinite(err)) and np.all(np.isfinite(xi))
        P = views.P
        assert np.array_equal(P, P.T)
        assert np.trace(P) <= n * alpha * (1 + 1e-12)
        assert np.linalg.eigvalsh(P).min() > 0
    # excitation returns: the estimate recovers
    u2, y2, _ = armax_data(rng, a, b, c, 6000, snr_db=40.0)
    _block(state, u2, y2, n)
    theta = views.theta
    assert np.max(np.abs(theta[:2] - theta_good[:2])) < 5e-2


values = st.one_of(
    st.just(0.0), st.floats(-1e300, 1e300), st.floats(-1e-300, 1e-300),
    st.sampled_from([1e308, -1e308, 5e-324, 1.0]),
)


@settings(max_examples=40, deadline=None)
@given(us=st.lists(values, min_size=1, max_size=60), ys=st.lists(values, min_size=1,
                                                                 max_size=60),
       lam=st.sampled_from([1.0, 0.99, 0.5]))
def test_no_nan_leaves_the_estimator(us, ys, lam):
    m = min(len(us), len(ys))
    est = RelsEstimator(na=2, nb=1, nc=2, forgetting=lam)
    e = est.update_many(np.array(us[:m]), np.array(ys[:m]))
    for uk, yk in zip(us, ys, strict=False):
        e = np.r_[e, est.update(uk, yk)]
    assert not np.any(np.isnan(e))
    assert np.all(np.isfinite(est.theta))
    P = est.P
    assert np.all(np.isfinite(P)) and np.array_equal(P, P.T)
    assert not np.any(np.isnan(est.model.theta))
