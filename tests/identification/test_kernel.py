"""The compiled RELS/RML kernel against the slow numpy reference (tests/identification/naive.py)."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from ehss.identification import _kernels as K
from ehss.identification.rels import RelsEstimator, _new_state

from .naive import naive_rels
from .systems import armax_data, system


def _run_kernel(u, y, na, nb, nc, delay, lam, alpha, trace_bound=None, c_radius=0.99,
                alpha_c=None, method="rels"):
    n = na + nb + 1 + nc
    ac = alpha if alpha_c is None else alpha_c
    tb = (na + nb + 1) * alpha + nc * ac if trace_bound is None else trace_bound
    state = _new_state(na, nb, nc, delay, lam, alpha, tb, c_radius, np.zeros(n), alpha_c,
                       method)
    err, xi = np.empty(u.size), np.empty(u.size)
    K.rels_run(state, u, y, err, xi, np.empty((0, n)), 1)
    theta, P, *_ = K.state_views(state)
    return theta.copy(), P.copy(), err, xi, state


CASES = [
    ((2, 1, 1, 1), 1.0, 1e6, None, None),
    ((4, 2, 2, 1), 0.995, 1e3, None, None),
    ((3, 2, 0, 0), 0.98, 1e2, 50.0, None),  # trace bound active
    ((2, 0, 2, 2), 1.0, 1e4, None, None),
    ((4, 2, 2, 1), 1.0, 1e10, None, 1e2),  # separate P(0) of the c-part
]
RML_CASES = [
    ((4, 3, 4, 1), 1.0, 1e10, None, 1e2),  # nc = na, the output-error use
    ((3, 1, 2, 1), 0.99, 1e3, None, None),
    ((2, 1, 1, 0), 0.995, 1e4, 20.0, None),  # trace bound active
    ((6, 5, 6, 1), 0.999, 1e6, None, 1e2),
    ((3, 2, 0, 1), 0.98, 1e2, None, None),  # nc = 0: RML is RLS
]


@pytest.mark.parametrize("method", ["rels", "rml"])
@pytest.mark.parametrize(("orders", "lam", "alpha", "trace_bound", "alpha_c"), CASES)
def test_kernel_equals_naive(rng, orders, lam, alpha, trace_bound, alpha_c, method):
    _check_against_naive(rng, orders, lam, alpha, trace_bound, alpha_c, method)


@pytest.mark.parametrize(("orders", "lam", "alpha", "trace_bound", "alpha_c"), RML_CASES)
def test_rml_kernel_equals_naive(rng, orders, lam, alpha, trace_bound, alpha_c):
    _check_against_naive(rng, orders, lam, alpha, trace_bound, alpha_c, "rml")


def _check_against_naive(rng, orders, lam, alpha, trace_bound, alpha_c, method):
    na, nb, nc, d = orders
    a, b, c = system(4)
    u, y, _ = armax_data(rng, a, b, c, 1500, snr_db=20.0)
    u, y = u / np.std(u), y / np.std(y)
    ref = naive_rels(u, y, na=na, nb=nb, nc=nc, delay=d, lam=lam, alpha=alpha,
                     trace_bound=trace_bound, alpha_c=alpha_c, method=method)
    theta, P, err, xi, state = _run_kernel(u, y, na, nb, nc, d, lam, alpha, trace_bound,
                                           alpha_c=alpha_c, method=method)
    # same algorithm, different summation order only (BLAS vs loops): 1e-12
    assert_allclose(theta, ref[0], rtol=1e-12, atol=1e-12)
    assert_allclose(err, ref[2], rtol=1e-12, atol=1e-12)
    assert_allclose(xi, ref[3], rtol=1e-12, atol=1e-12)
    scale = np.max(np.abs(ref[1]))
    assert_allclose(P, ref[1], rtol=1e-12, atol=1e-12 * scale)
    assert state[K.H_RESETS] == ref[4]["resets"]
    assert state[K.H_CPROJ] == ref[4]["c_projections"]
    assert state[K.H_TRSCALE] == ref[4]["trace_scalings"]
    if trace_bound is not None:
        assert ref[4]["trace_scalings"] > 0
    assert np.array_equal(P, P.T)  # exactly symmetric by construction
    if method == "rml" and nc > 0:
        # the filtered regressor really differs from ψ̂ (else RML would be RELS)
        plain = naive_rels(u, y, na=na, nb=nb, nc=nc, delay=d, lam=lam, alpha=alpha,
                           trace_bound=trace_bound, alpha_c=alpha_c)
        assert np.max(np.abs(plain[0] - ref[0])) > 1e-6


@pytest.mark.parametrize(("orders", "lam", "alpha", "trace_bound", "alpha_c"),
                         RML_CASES[:3])
def test_rml_streaming_equals_naive(rng, orders, lam, alpha, trace_bound, alpha_c):
    # the streaming estimator runs the same step one dispatch per sample (unit scales,
    # so it sees the same numbers as the reference): 1e-12 as for the batch kernel
    na, nb, nc, d = orders
    a, b, c = system(4)
    u, y, _ = armax_data(rng, a, b, c, 1200, snr_db=20.0)
    u, y = u / np.std(u), y / np.std(y)
    ref = naive_rels(u, y, na=na, nb=nb, nc=nc, delay=d, lam=lam, alpha=alpha,
                     trace_bound=trace_bound, alpha_c=alpha_c, method="rml")
    est = RelsEstimator(na=na, nb=nb, nc=nc, delay=d, forgetting=lam, p0=alpha,
                        p0_c=alpha_c, trace_bound=trace_bound, method="rml")
    err = np.array([est.update(uk, yk) for uk, yk in zip(u[:700], y[:700], strict=True)])
    err = np.r_[err, est.update_many(u[700:], y[700:])]
    assert_allclose(err, ref[2], rtol=1e-12, atol=1e-12)
    assert_allclose(est.theta, ref[0], rtol=1e-12, atol=1e-12)
    assert_allclose(est.P, ref[1], rtol=1e-12, atol=1e-12 * np.max(np.abs(ref[1])))
    assert est.model.meta["method"] == "rml-streaming"


def test_rml_reset_clears_filtered_history(rng):
    # data never make P indefinite here, so corrupt P mid-run (as rounding could) and
    # check that the guard resets P *and* restarts the 1/Ĉ filter from rest: the
    # sample's ψ_f is then ψ̂ itself and the older rows are zero
    na, nb, nc, d = 2, 1, 2, 1
    a, b, c = system(2)
    u, y, _ = armax_data(rng, a, b, c, 600, snr_db=20.0)
    u, y = u / np.std(u), y / np.std(y)
    n = na + nb + 1 + nc
    st = _new_state(na, nb, nc, d, 1.0, 1e3, n * 1e3, 0.99, np.zeros(n), None, "rml")
    err, xi = np.empty(300), np.empty(300)
    K.rels_run(st, u[:300], y[:300], err, xi, np.empty((0, n)), 1)
    hf = K.state_views(st)[6]
    assert np.any(hf[1:] != 0.0)  # the filter carries history
    P = K.state_views(st)[1]
    P[:] = -np.eye(n)  # indefinite: ψ_fᵀPψ_f < 0 on the next sample
    K.rels_step(st, u[300], y[300])
    assert st[K.H_RESETS] == 1
    # after the reset ψ_f(300) = ψ̂(300) (zero history), now shifted into row 1
    psi_300 = np.r_[-y[299], -y[298], u[299], u[298], xi[299], xi[298]]
    assert_allclose(hf[1], psi_300, rtol=0, atol=0)
    assert np.all(hf[2] == 0.0)


def test_c_projection_matches_naive(rng):
    # C driven out of the unit disc: a deliberately wrong C with a tight radius
    u = rng.standard_normal(800)
    y = np.cumsum(rng.standard_normal(800)) * 0.1
    ref = naive_rels(u, y, na=1, nb=0, nc=2, delay=1, lam=0.99, alpha=1e3, c_radius=0.5)
    theta, P, err, xi, state = _run_kernel(u, y, 1, 0, 2, 1, 0.99, 1e3, c_radius=0.5)
    assert ref[4]["c_projections"] > 0
    assert state[K.H_CPROJ] == ref[4]["c_projections"]
    # root reflection via eigvals (kernel) vs np.roots (reference): 1e-12
    assert_allclose(theta, ref[0], rtol=1e-12, atol=1e-12)
    assert np.max(np.abs(np.roots(np.r_[1.0, theta[2:]]))) <= 0.5 + 1e-12


@pytest.mark.parametrize("c", [[0.5], [-1.2], [0.3, 0.2], [1.5, 0.9], [-1.8, 0.81],
                               [0.1, -0.2, 0.3, 0.96], [2.0, 1.5, 0.5]])
def test_schur_cohn_matches_roots(c):
    c = np.array(c)
    for radius in (0.99, 0.9, 0.5):
        expect = np.max(np.abs(np.roots(np.r_[1.0, c]))) < radius
        # the coefficients sit at an offset inside θ̂ (here after two other entries)
        theta = np.r_[7.0, -7.0, c]
        assert K._c_within(theta, 2, c.size, radius, np.zeros(c.size + 1)) == expect
