"""The 4-wide P-update kernels (identification/_simd.py) and the RELS batch loop, bit for bit.

The intrinsics are checked against plain numpy doing the documented arithmetic, for
every vector count they are generated for (and the plain-loop fallbacks beyond
SIMD_MAX); the RELS batch loop (fused gain, counters in locals, written out) against
the streaming step, sample by sample.
"""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit
from numpy.testing import assert_allclose, assert_array_equal

from ehss.identification import _kernels as K
from ehss.identification._simd import SIMD_MAX, downdate_gain, gain_sums
from ehss.identification.rels import _new_state

from .systems import armax_data, system


def _tree(values, op):
    """Pairwise, level by level: (v0 ∘ v1), (v2 ∘ v3), …; an odd last value moves up."""
    while len(values) > 1:
        values = [op(values[i], values[i + 1]) if i + 1 < len(values) else values[i]
                  for i in range(0, len(values), 2)]
    return values[0]


def _trace_min(P, n):
    """(tr P, min P_ii) as documented: the pairwise tree up to SIMD_MAX, else in order."""
    d = [P[i, i] for i in range(n)]
    if P.shape[0] <= SIMD_MAX:
        return _tree(d, lambda a, b: a + b), _tree(d, lambda a, b: a if a < b else b)
    tr = 0.0
    for x in d:
        tr += x
    return tr, min(d)


def _reference(P, g, r, n, inv_den, inv_lam, fused):
    """Row i < n: P_i ← P_i·inv_lam − w_i w, w = g √(inv_den·inv_lam) (fused: no
    inv_lam); then g = Σ_i P_i r_i in order, and tr P, min P_ii."""
    P = P.copy()
    w = g * np.sqrt(inv_den if fused else inv_den * inv_lam)
    for i in range(n):
        if not fused:
            P[i] = P[i] * inv_lam
        P[i] = P[i] - w[i] * w
    tr, dmin = _trace_min(P, n)
    gn = np.zeros(P.shape[0])
    for i in range(n):
        gn = gn + P[i] * r[i]
    return P, gn, tr, dmin


@njit
def _call_downdate(P, g, n, inv_den, inv_lam):
    return K._downdate(P, g, n, inv_den, inv_lam)


@njit
def _call_downdate_gain(P, g, r, n, inv_den, theta):
    return downdate_gain(P, g, r, n, inv_den, theta)


@njit
def _call_gain_sums(P, g, r, n, theta):
    return gain_sums(P, g, r, n, theta)


def _vector_dot(p, q):
    """Σ p_j q_j as documented: 4-wide products in the pairwise tree, then the lanes."""
    v = _tree([p[c:c + 4] * q[c:c + 4] for c in range(0, p.size, 4)], lambda a, b: a + b)
    return (v[0] + v[1]) + (v[2] + v[3])


def _sums(r, theta, g, n):
    """(rᵀθ, rᵀg, max(0, max|g_j|)) as the vector kernels form them."""
    return _vector_dot(r, theta), _vector_dot(r, g), max(0.0, np.max(np.abs(g[:n])))


def _problem(rng, m, n):
    A = rng.standard_normal((n, n))
    P = np.zeros((m, m))
    P[:n, :n] = A @ A.T + n * np.eye(n)
    r = np.zeros(m)
    r[:n] = rng.standard_normal(n)
    return P, P @ r, r  # g = P r as in (21)


def _theta(rng, m, n):
    theta = np.zeros(m)
    theta[:n] = rng.standard_normal(n)
    return theta


# every vector count of the intrinsic (m = 4..32), n = m and n < m (zero padding), and
# two sizes beyond SIMD_MAX that take the plain loops
SIZES = [(4 * k, 4 * k - j) for k in range(1, SIMD_MAX // 4 + 1) for j in (0, 3) if 4 * k - j > 0]
SIZES += [(SIMD_MAX + 4, SIMD_MAX + 1), (SIMD_MAX + 8, SIMD_MAX + 8)]


@pytest.mark.parametrize(("m", "n"), [(m, n) for m, n in SIZES if m <= SIMD_MAX])
def test_downdate_gain_bit_for_bit(rng, m, n):
    P, g, r = _problem(rng, m, n)
    inv_den = 1.0 / (1.0 + r @ g)
    P_ref, gn_ref, tr_ref, dmin_ref = _reference(P, g, r, n, inv_den, 1.0, fused=True)
    P_k, g_k = P.copy(), g.copy()
    theta = _theta(rng, m, n)
    out = _call_downdate_gain(P_k, g_k, r, n, inv_den, theta)
    assert_array_equal(P_k, P_ref)
    assert_array_equal(g_k, gn_ref)
    assert_array_equal(P_k, P_k.T)
    assert out[:3] == _sums(r, theta, gn_ref, n)  # ŷ, s, max|g| of the next sample
    assert out[3:] == (tr_ref, dmin_ref)
    # the mathematics: P − g gᵀ/den and the next gain P r
    P_math = P - np.outer(g, g) * inv_den
    assert_allclose(P_k, P_math, rtol=0, atol=1e-13 * np.abs(P).max())
    assert_allclose(g_k, P_math @ r, rtol=0, atol=1e-12 * (np.abs(P_math) @ np.abs(r)).max())


@pytest.mark.parametrize(("m", "n"), [(m, n) for m, n in SIZES if m <= SIMD_MAX])
def test_gain_sums_bit_for_bit(rng, m, n):
    P, _, r = _problem(rng, m, n)
    r[:n] *= np.where(np.arange(n) % 2 == 0, 1.0, -1.0)  # mixed signs in g
    g_ref = np.zeros(m)
    for i in range(n):  # rows of the symmetric P as columns, summed left to right
        g_ref = g_ref + P[i] * r[i]
    theta, g = _theta(rng, m, n), np.full(m, np.nan)
    out = _call_gain_sums(P, g, r, n, theta)
    assert_array_equal(g, g_ref)
    assert out == _sums(r, theta, g_ref, n)
    assert out[0] == pytest.approx(r @ theta, rel=1e-13, abs=1e-13)
    assert out[1] == pytest.approx(r @ g_ref, rel=1e-13)
    assert out[2] == np.max(np.abs(g_ref[:n])) > 0.0


@njit
def _call_gain(P, r, g, n):
    K._gain(P, r, g, n)


@pytest.mark.parametrize(("m", "n"), SIZES)
def test_gain_bit_for_bit(rng, m, n):
    P, _, r = _problem(rng, m, n)
    g_ref = np.zeros(m)
    for i in range(n):  # rows of the symmetric P as columns, summed left to right
        g_ref = g_ref + P[i] * r[i]
    g = np.full(m, np.nan)  # every entry must be written
    _call_gain(P, r, g, n)
    assert_array_equal(g, g_ref)


@pytest.mark.parametrize(("m", "n"), SIZES)
@pytest.mark.parametrize("lam", [1.0, 0.97])
def test_downdate_bit_for_bit(rng, m, n, lam):
    P, g, r = _problem(rng, m, n)
    inv_den = 1.0 / (lam + r @ g)
    P_ref, _, tr_ref, dmin_ref = _reference(P, g, r, n, inv_den, 1.0 / lam, fused=False)
    P_k = P.copy()
    tr, dmin = _call_downdate(P_k, g.copy(), n, inv_den, 1.0 / lam)
    assert_array_equal(P_k, P_ref)
    assert (tr, dmin) == (tr_ref, dmin_ref)
    assert_array_equal(P_k, P_k.T)
    P_math = (P - np.outer(g, g) * inv_den) / lam  # eq (22)
    assert_allclose(P_k, P_math, rtol=0, atol=1e-13 * np.abs(P_math).max())
    assert tr == pytest.approx(np.trace(P_k), rel=1e-14)


def test_downdate_reports_a_lost_diagonal(rng):
    # a downdate that makes P_00 negative must show in dmin (the guard resets on it)
    P, g, r = _problem(rng, 8, 6)
    g[0] = 10.0 * np.sqrt(P[0, 0])
    P_k = P.copy()
    tr, dmin = _call_downdate(P_k, g.copy(), 6, 1.0, 1.0)
    assert dmin == P_k[0, 0] < 0.0
    assert tr == pytest.approx(np.trace(P_k))
    # the fused kernel reports the same from its own read-back of the diagonal
    P_k = P.copy()
    out = _call_downdate_gain(P_k, g.copy(), r, 6, 1.0, _theta(rng, 8, 6))
    assert out[4] == P_k[0, 0] < 0.0
    assert out[3] == _trace_min(P_k, 6)[0]


CASES = [
    ((2, 1, 1, 1), 1.0, 1e6, None),
    ((4, 2, 2, 1), 0.995, 1e3, None),
    ((3, 2, 0, 0), 0.98, 1e2, 50.0),  # trace bound active
    ((6, 6, 4, 1), 1.0, 1e6, None),
    ((6, 6, 4, 1), 1.0, 1e6, 2e3),  # trace bound at λ = 1: fused pass undone
    ((20, 10, 4, 1), 1.0, 1e4, None),  # n = 35 > SIMD_MAX: plain loops
    ((20, 10, 4, 1), 0.99, 1e4, None),
]


@pytest.mark.parametrize(("orders", "lam", "alpha", "trace_bound"), CASES)
def test_rels_batch_equals_streaming_bit_for_bit(rng, orders, lam, alpha, trace_bound):
    na, nb, nc, d = orders
    n = na + nb + 1 + nc
    a, b, c = system(4)
    u, y, _ = armax_data(rng, a, b, c, 1500, snr_db=20.0)
    u, y = u / np.std(u), y / np.std(y)
    y[700:760] = 0.0  # a dead stretch, then excitation returns
    tb = n * alpha if trace_bound is None else trace_bound

    def fresh():
        return _new_state(na, nb, nc, d, lam, alpha, tb, 0.99, np.zeros(n))

    batch = fresh()
    err_b, xi_b = np.empty(u.size), np.empty(u.size)
    hist = np.empty((u.size // 7, n))
    K.rels_run(batch, u, y, err_b, xi_b, hist, 7)
    stream = fresh()
    err_s = np.empty(u.size)
    hist_s = []
    for k in range(u.size):
        err_s[k] = K.rels_step(stream, u[k], y[k])
        if (k + 1) % 7 == 0:
            hist_s.append(K.state_views(stream)[0].copy())
    assert_array_equal(err_b, err_s)
    assert_array_equal(hist, np.array(hist_s)[: hist.shape[0]])
    # the whole state but the two work buffers (g, and cw of the Schur–Cohn test)
    views_b, views_s = K.state_views(batch), K.state_views(stream)
    for name, i in (("theta", 0), ("P", 1), ("psi", 2), ("u line", 4), ("RML rows", 6)):
        assert_array_equal(views_b[i], views_s[i], err_msg=name)
    # counters, ξ̂, noise variance
    assert_array_equal(batch[:K.HEADER], stream[:K.HEADER])
    if trace_bound is not None:
        assert batch[K.H_TRSCALE] > 0


def test_rels_batch_restart_equals_streaming(rng):
    # an indefinite P (as rounding could leave it) must restart both paths identically
    na, nb, nc, d = 2, 1, 2, 1
    n = na + nb + 1 + nc
    a, b, c = system(2)
    u, y, _ = armax_data(rng, a, b, c, 900, snr_db=20.0)
    u, y = u / np.std(u), y / np.std(y)
    states = []
    for path in ("batch", "stream"):
        st = _new_state(na, nb, nc, d, 1.0, 1e4, n * 1e4, 0.99, np.zeros(n))
        K.rels_run(st, u[:400], y[:400], np.empty(400), np.empty(400), np.empty((0, n)), 1)
        K.state_views(st)[1][:] = -np.eye(n)  # ψ̂ᵀPψ̂ < 0 on the next sample
        if path == "batch":
            K.rels_run(st, u[400:], y[400:], np.empty(500), np.empty(500),
                       np.empty((0, n)), 1)
        else:
            for k in range(400, 900):
                K.rels_step(st, u[k], y[k])
        states.append(st)
    assert states[0][K.H_RESETS] == states[1][K.H_RESETS] == 1
    for i in (0, 1, 2):  # θ̂, P, ψ̂
        assert_array_equal(K.state_views(states[0])[i], K.state_views(states[1])[i])


def test_rels_batch_in_chunks_equals_one_batch(rng):
    # records split anywhere (also shorter than the u line, d + nb + 1 = 6 here) must
    # continue exactly where the previous part stopped
    na, nb, nc, d = 4, 3, 2, 2
    n = na + nb + 1 + nc
    a, b, c = system(4)
    u, y, _ = armax_data(rng, a, b, c, 1000, snr_db=20.0)
    u, y = u / np.std(u), y / np.std(y)
    whole = _new_state(na, nb, nc, d, 1.0, 1e4, n * 1e4, 0.99, np.zeros(n))
    err = np.empty(u.size)
    K.rels_run(whole, u, y, err, np.empty(u.size), np.empty((0, n)), 1)
    parts = _new_state(na, nb, nc, d, 1.0, 1e4, n * 1e4, 0.99, np.zeros(n))
    err_p = []
    edges = [0, 1, 3, 8, 9, 400, 404, 1000]
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        e = np.empty(hi - lo)
        K.rels_run(parts, u[lo:hi], y[lo:hi], e, np.empty(hi - lo), np.empty((0, n)), 1)
        err_p.append(e)
    assert_array_equal(np.concatenate(err_p), err)
    for i in (0, 1, 2, 4):  # θ̂, P, ψ̂, u line
        assert_array_equal(K.state_views(parts)[i], K.state_views(whole)[i])


@pytest.mark.parametrize("orders", [(1, 0, 0, 0), (2, 1, 1, 1), (4, 4, 2, 1), (6, 6, 4, 1),
                                    (7, 7, 3, 0), (20, 10, 4, 1)])
def test_state_buffer_aligns_P(orders):
    # P's rows are whole 32-byte vectors on 64-byte boundaries whatever the allocator
    # returned, and the buffer behaves as a plain zeroed state of the right size
    n = sum(orders[:3]) + 1
    for _ in range(5):
        st = _new_state(*orders, 1.0, 1e3, 1e6, 0.99, np.zeros(n))
        P_full = K._views.py_func(st)[1]
        assert P_full.ctypes.data % 64 == 0
        assert P_full.shape[1] % 4 == 0
        assert st.size == K.state_size(*orders)
        assert np.array_equal(np.diag(K.state_views(st)[1]), np.full(n, 1e3))
