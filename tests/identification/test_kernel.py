"""The compiled RELS/RML kernel against the independent numpy reference (naive.py).

Tolerances come from the conditioning of each record, measured rather than guessed:
the reference is run twice, in float64 and in extended precision (np.longdouble, a
64-bit mantissa, ~2 000× finer). The float64 run's distance from the extended one is
what this record's recursion does to rounding (the first downdates from P(0) = αI
cancel all but ~1/(α|ψ|²) of P, so rounding there is amplified by up to α|ψ|², and
root reflection amplifies it again). The kernel is another float64 implementation
of the same equations in another operation order, so it must be as close to the
extended-precision answer as the float64 reference is, up to the constants of the two
operation orders (the kernel's square-root rank-1 update and four partial sums,
companion eigenvalues against np.roots): within 30× that distance (the largest ratio
in this suite is 12; one wrong setting in the kernel gives 10¹², see
test_reference_detects_a_wrong_kernel), and never asked for better than √size·eps
relative (a record on which the reference happens to be exact to the last bit).
Discrete decisions (resets, projections, trace scalings) must agree exactly.
"""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit
from numpy.testing import assert_allclose
from scipy.signal import lfilter

from ehss.identification import _kernels as K
from ehss.identification._common import block_counters, new_state
from ehss.identification.rels import RelsEstimator

from .naive import naive_rels
from .systems import armax_data, kernel_settings, system

EPS = np.finfo(float).eps


# the kernel's helpers have no Python entry point (no CPython wrapper: it would cost
# cold-compile time for nothing), so the tests call them from a kernel of their own
@njit
def _c_within(theta, o, nc, radius, cw):
    return K._c_within(theta, o, nc, radius, cw)


@njit
def _poly_roots(c, re, im):
    K._poly_roots(c, re, im)


def _run_kernel(u, y, na, nb, nc, delay, lam, alpha, trace_bound=None, c_radius=0.99,
                alpha_c=None, method="rels", loop=K.rels_run):
    n = na + nb + 1 + nc
    ac = alpha if alpha_c is None else alpha_c
    tb = (na + nb + 1) * alpha + nc * ac if trace_bound is None else trace_bound
    settings = kernel_settings(na, nb, nc, delay, lam, alpha, ac, tb, c_radius, method)
    block, views = new_state(settings, np.zeros(n))
    rec = K.record(u, y)
    assert loop(block, rec, np.empty((0, n)), 1, True) == u.size
    return views.theta.copy(), views.P.copy(), rec[2], rec[3], block_counters(block), views


def _assert_close_to_exact(got, ref64, exact, name):
    """|got − exact| ≤ 30·|ref64 − exact| + √size·eps·scale, in the max norm."""
    exact = np.asarray(exact, dtype=float)
    scale = np.max(np.abs(exact))
    ref_error = np.max(np.abs(np.asarray(ref64) - exact))
    bound = 30.0 * ref_error + exact.size**0.5 * EPS * scale
    error = np.max(np.abs(got - exact))
    assert error <= bound, f"{name}: kernel error {error:.3g} > bound {bound:.3g}"


def _record(rng, kind, n_samples=800):
    a, b, c = system(4)
    if kind == "band-limited":  # oversampled 2–100 Hz: an ill-conditioned regressor
        u, y, _ = armax_data(rng, a, b, c, n_samples, snr_db=20.0)
    else:  # white input: a well-conditioned regressor
        u = rng.standard_normal(n_samples)
        y = lfilter(np.r_[0.0, b], a, u) + 0.1 * lfilter(c, a, rng.standard_normal(u.size))
    return u / np.std(u), y / np.std(y)


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


@pytest.mark.parametrize("kind", ["band-limited", "white"])
@pytest.mark.parametrize(("orders", "lam", "alpha", "trace_bound", "alpha_c"), CASES)
def test_kernel_matches_reference(rng, orders, lam, alpha, trace_bound, alpha_c, kind):
    _check_against_naive(rng, orders, lam, alpha, trace_bound, alpha_c, "rels", kind)


@pytest.mark.parametrize(("orders", "lam", "alpha", "trace_bound", "alpha_c"),
                         CASES[::2] + RML_CASES)
def test_rml_kernel_matches_reference(rng, orders, lam, alpha, trace_bound, alpha_c):
    _check_against_naive(rng, orders, lam, alpha, trace_bound, alpha_c, "rml",
                         "band-limited")


def _check_against_naive(rng, orders, lam, alpha, trace_bound, alpha_c, method, kind,
                         loop=K.rels_run):
    na, nb, nc, d = orders
    u, y = _record(rng, kind)
    kw = dict(na=na, nb=nb, nc=nc, delay=d, lam=lam, alpha=alpha, trace_bound=trace_bound,
              alpha_c=alpha_c, method=method)
    ref = naive_rels(u, y, **kw)
    exact = naive_rels(u, y, **kw, dtype=np.longdouble)
    theta, P, err, xi, counters, _ = _run_kernel(u, y, na, nb, nc, d, lam, alpha,
                                                 trace_bound, alpha_c=alpha_c,
                                                 method=method, loop=loop)
    for got, i, name in ((theta, 0, "theta"), (P, 1, "P"), (err, 2, "e"), (xi, 3, "xi")):
        _assert_close_to_exact(got, ref[i], exact[i], name)
    for key in ("resets", "c_projections", "trace_scalings"):
        assert counters[key] == ref[4][key] == exact[4][key], key
    if trace_bound is not None:
        assert ref[4]["trace_scalings"] > 0
    assert np.array_equal(P, P.T)  # exactly symmetric by construction
    assert np.linalg.eigvalsh(P).min() > 0
    if method == "rml" and nc > 0:
        # the filtered regressor really differs from ψ̂ (else RML would be RELS)
        plain = naive_rels(u, y, **{**kw, "method": "rels"})
        assert np.max(np.abs(plain[0] - ref[0])) > 1e-6


def test_reference_detects_a_wrong_kernel(rng):
    # the comparison can fail: the same kernel with λ = 0.999 instead of 1 (a slip a
    # refactor could make) is far outside the bound
    u, y = _record(rng, "white")
    kw = dict(na=2, nb=1, nc=1, delay=1, alpha=1e6)
    ref = naive_rels(u, y, **kw, lam=1.0)
    exact = naive_rels(u, y, **kw, lam=1.0, dtype=np.longdouble)
    theta = _run_kernel(u, y, 2, 1, 1, 1, 0.999, 1e6)[0]
    with pytest.raises(AssertionError, match="kernel error"):
        _assert_close_to_exact(theta, ref[0], exact[0], "theta")


@pytest.mark.parametrize(("orders", "lam", "alpha", "trace_bound", "alpha_c"),
                         RML_CASES[:3])
def test_rml_streaming_matches_reference(rng, orders, lam, alpha, trace_bound, alpha_c):
    # the streaming estimator runs the same step, one sample per call (unit scales, so
    # it sees the same numbers as the reference): the same bound as the batch kernel
    na, nb, nc, d = orders
    u, y = _record(rng, "band-limited", 1000)
    kw = dict(na=na, nb=nb, nc=nc, delay=d, lam=lam, alpha=alpha, trace_bound=trace_bound,
              alpha_c=alpha_c, method="rml")
    ref = naive_rels(u, y, **kw)
    exact = naive_rels(u, y, **kw, dtype=np.longdouble)
    est = RelsEstimator(na=na, nb=nb, nc=nc, delay=d, forgetting=lam, p0=alpha,
                        p0_c=alpha_c, trace_bound=trace_bound, method="rml")
    err = np.array([est.update(uk, yk) for uk, yk in zip(u[:700], y[:700], strict=True)])
    err = np.r_[err, est.update_many(u[700:], y[700:])]
    _assert_close_to_exact(err, ref[2], exact[2], "e")
    _assert_close_to_exact(est.theta, ref[0], exact[0], "theta")
    _assert_close_to_exact(est.P, ref[1], exact[1], "P")
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
    settings = kernel_settings(na, nb, nc, d, 1.0, 1e3, 1e3, n * 1e3, 0.99, "rml")
    block, views = new_state(settings, np.zeros(n))
    rec = K.record(u[:300], y[:300])
    K.rels_run(block, rec, np.empty((0, n)), 1, True)
    xi = rec[3]
    assert np.any(views.psi_f[1:] != 0.0)  # the filter carries history
    views.P[:] = -np.eye(n)  # indefinite: ψ_fᵀPψ_f < 0 on the next sample
    K.rels_run(block, K.record(u[300:301], y[300:301]), np.empty((0, n)), 1, False)
    # a run of no samples applies the pending P update
    K.rels_run(block, np.empty((4, 0)), np.empty((0, n)), 1, True)
    assert block_counters(block)["resets"] == 1
    # after the reset ψ_f(300) = ψ̂(300) (zero history), now shifted into row 1
    psi_300 = np.r_[-y[299], -y[298], u[299], u[298], xi[299], xi[298]]
    assert_allclose(views.psi_f[1], psi_300, rtol=0, atol=0)
    assert np.all(views.psi_f[2] == 0.0)
    # P restarted from P(0) = 1e3 I, then one downdate: definite again, trace below tr P(0)
    assert np.linalg.eigvalsh(views.P).min() > 0 and np.trace(views.P) < n * 1e3


def test_c_projection_matches_reference(rng):
    # C driven out of the unit disc: a deliberately wrong C with a tight radius
    u = rng.standard_normal(800)
    y = np.cumsum(rng.standard_normal(800)) * 0.1
    kw = dict(na=1, nb=0, nc=2, delay=1, lam=0.99, alpha=1e3, c_radius=0.5)
    ref = naive_rels(u, y, **kw)
    exact = naive_rels(u, y, **kw, dtype=np.longdouble)
    theta, P, err, xi, counters, _ = _run_kernel(u, y, 1, 0, 2, 1, 0.99, 1e3, c_radius=0.5)
    assert ref[4]["c_projections"] > 0
    assert counters["c_projections"] == ref[4]["c_projections"]
    _assert_close_to_exact(theta, ref[0], exact[0], "theta")
    # the projection keeps the roots inside the radius (1e-12: root-finding rounding)
    assert np.max(np.abs(np.roots(np.r_[1.0, theta[2:]]))) <= 0.5 + 1e-12


@pytest.mark.parametrize("c", [[0.5], [-1.2], [0.3, 0.2], [1.5, 0.9], [-1.8, 0.81],
                               [0.1, -0.2, 0.3, 0.96], [2.0, 1.5, 0.5]])
def test_schur_cohn_matches_roots(c):
    c = np.array(c)
    for radius in (0.99, 0.9, 0.5):
        expect = np.max(np.abs(np.roots(np.r_[1.0, c]))) < radius
        # the coefficients sit at an offset inside θ̂ (here after two other entries)
        theta = np.r_[7.0, -7.0, c]
        assert _c_within(theta, 2, c.size, radius, np.zeros(c.size + 1)) == expect


def test_settings_round_trip_through_the_block():
    s = kernel_settings(3, 2, 1, 2, 0.99, 1e6, 1e2, 5e6, 0.9, "rml", enabled=False)
    block = K.new_block(s)
    assert K.settings_of(block) == s
    K.set_enabled(block, True)
    assert K.settings_of(block) == s._replace(enabled=True)


def test_state_views_tile_the_block_on_lines():
    # after the header (settings, counters, noise variance) the named views follow one
    # another without overlap, each on a 64-byte line of the line-aligned block, with
    # less than a line of padding before each; the streaming sample (io) ends the block
    s = kernel_settings(3, 2, 2, 2, 1.0, 1e6, 1e6, 8e6, 0.99, "rels")
    block = K.new_block(s)
    assert block.ctypes.data % (8 * K.LINE) == 0
    owner = np.full(block.size, -1)
    owner[: K.HEADER] = -2
    views = K.state_views(block)
    starts = [(view.ctypes.data - block.ctypes.data) // 8 for view in views]
    for k in np.argsort(starts):  # in the order they lie in the block
        view, start = views[k], starts[k]
        assert start % K.LINE == 0 and start >= K.HEADER
        assert np.all(owner[start : start + view.size] == -1), "views overlap"
        padding = start - (np.flatnonzero(owner != -1).max() + 1)
        assert 0 <= padding < K.LINE
        owner[start : start + view.size] = k
    assert owner[-1] == K.RelsState._fields.index("io")  # io ends the block
    # every float of a view is the block's own (views, not copies)
    block[K.HEADER :] = np.arange(block.size - K.HEADER)
    for k, view in enumerate(views):
        assert_allclose(view.ravel(), block[owner == k], rtol=0, atol=0)


def test_poly_roots_match_numpy(rng):
    # simple roots: the iteration converges quadratically, to a few eps of the roots'
    # magnitude like np.roots' eigenvalues (1e-12 leaves 4 digits of margin); a double
    # root is ill-conditioned for any method: ~√eps ≈ 1.5e-8, 1e-7 allowed
    def roots(c):
        re, im = np.empty(c.size), np.empty(c.size)
        _poly_roots(c, re, im)
        return re + 1j * im

    for nc in range(1, 9):
        for _ in range(20):
            c = rng.standard_normal(nc) * rng.choice([0.1, 1.0, 3.0])
            got = roots(c)
            ref = np.roots(np.r_[1.0, c])
            scale = max(1.0, np.max(np.abs(ref)))
            for z in ref:
                assert np.min(np.abs(got - z)) <= 1e-12 * scale
    double = roots(np.array([-1.8, 0.81]))  # (z − 0.9)²
    assert_allclose(double, [0.9, 0.9], atol=1e-7)


# ---------------------------------------------------------------- specialised loops
#: the orders of the specialised-loop tests: one set, so one compile (seconds)
SPECIALISED = (4, 2, 2, 1)
SPECIALISED_CASES = [  # (λ, α, trace bound, α_c, method, kind)
    (0.995, 1e3, None, None, "rels", "band-limited"),  # forgetting: floor and 1/λ
    (1.0, 1e10, None, 1e2, "rels", "white"),  # λ = 1: the pass without the multiply
    (0.98, 1e2, 50.0, None, "rels", "white"),  # trace bound active
    (1.0, 1e10, None, 1e2, "rml", "band-limited"),
    (0.99, 1e3, None, None, "rml", "band-limited"),
]


@pytest.mark.slow
@pytest.mark.parametrize(("lam", "alpha", "trace_bound", "alpha_c", "method", "kind"),
                         SPECIALISED_CASES)
def test_specialised_loop_matches_reference(rng, lam, alpha, trace_bound, alpha_c, method,
                                            kind):
    # the loop compiled with the orders as constants, against the independent reference
    # with the bounds of the generic loop (the same operations, so the same distance
    # from the extended-precision answer); every safeguard path is on in some case
    loop = K.kernel_for(*SPECIALISED, compile_now=True)
    assert loop is not K.rels_run.compile(K.RELS_RUN_SIGNATURE)
    _check_against_naive(rng, SPECIALISED, lam, alpha, trace_bound, alpha_c, method, kind,
                         loop=loop)


@pytest.mark.slow
@pytest.mark.parametrize("method", ["rels", "rml"])
def test_specialised_loop_is_the_generic_loop_bit_for_bit(rng, method):
    # the same operations in the same order: any difference (0 tolerance) would be a
    # constant that does not match the block it runs on; C projections and a trace
    # bound are forced (tight radius and bound) so that the rare paths run too
    u, y = _record(rng, "band-limited")
    kw = dict(lam=0.99, alpha=1e3, trace_bound=20.0, c_radius=0.3, method=method)
    spec = _run_kernel(u, y, *SPECIALISED, **kw, loop=K.kernel_for(*SPECIALISED,
                                                                   compile_now=True))
    generic = _run_kernel(u, y, *SPECIALISED, **kw)
    assert generic[4]["c_projections"] > 0 and generic[4]["trace_scalings"] > 0
    assert spec[4] == generic[4]
    for a, b in zip(spec[:4], generic[:4], strict=True):
        assert np.array_equal(a, b)


def test_kernel_for_is_generic_until_asked(monkeypatch):
    # orders never specialised (and not in the disk cache) run on the generic loop
    monkeypatch.setattr(K, "_cached_on_disk", lambda run, sig: False)
    assert K.kernel_for(9, 0, 0, 3) is K.rels_run.compile(K.RELS_RUN_SIGNATURE)
