"""The PEM fit's reduced least-squares problem against the full one it stands for.

Levenberg–Marquardt is given the residual [q; ρ] and Jacobian [R; 0] of n + 1 rows
instead of ε and J of N rows (:class:`ehss.identification.pem._Predictor`). Its steps,
costs and convergence tests are those of the full problem iff
‖q + R p‖² + ρ² = ‖ε + J p‖² for every step p, which is checked here for random steps
against ε and J formed explicitly, through both ways of forming R (Cholesky of JᵀJ on a
well-conditioned record, QR of [J ε] on an oversampled one); and MINPACK run on both
forms from the same start must take the same path.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares
from scipy.signal import lfilter

from ehss.identification import _pem_kernels as pk
from ehss.identification.pem import _Predictor

from .systems import band_limited, resonance_poles


def _record(rng, n, oversampled):
    """A 4th-order loop (resonances at 0.4 and 1 Hz, ζ 0.3) sampled at 6 Hz and driven by
    white noise, or, ``oversampled``, a 6th-order one (0.3, 0.7 and 1.2 Hz) sampled at
    1 kHz and driven by noise band-limited to 0.02–1 Hz (the Jacobian's columns then
    nearly collinear: κ ≈ 4e5); 30 dB SNR. Returns u, y and A."""
    fs = 1000.0 if oversampled else 6.0
    freqs = (0.3, 0.7, 1.2) if oversampled else (0.4, 1.0)
    a = np.real(np.poly(sum((resonance_poles(f, 0.3, fs) for f in freqs), [])))
    u = band_limited(rng, n, 0.02, 1.0, fs) if oversampled else rng.standard_normal(n)
    y = lfilter([0.0, 1.0, 0.5], a, u)
    y = y + np.std(y) * 10 ** (-30 / 20) * rng.standard_normal(n)
    return u / np.std(u), y / np.std(y), a


def _problem(rng, oversampled, oe):
    """A predictor on the record and θ at its A, a random B and C = (1 − 0.5q⁻¹)(1 +
    0.3q⁻¹)."""
    u, y, a = _record(rng, 4000, oversampled)
    na, nb, nc, d = (a.size - 1, 2, 0 if oe else 2, 1)
    k0 = max(na, nb + d, nc)
    p = _Predictor(u, y, na, nb, nc, d, k0, 0.999, oe=oe)
    theta = np.concatenate([a[1:], rng.standard_normal(nb + 1),
                            [] if oe else np.real(np.poly([0.5, -0.3]))[1:]])
    return p, theta


@pytest.mark.parametrize("oe", [False, True])
@pytest.mark.parametrize("oversampled", [False, True])
def test_reduced_problem_has_the_costs_of_the_full_one(rng, oversampled, oe):
    p, theta = _problem(rng, oversampled, oe)
    eps, J = p.residual(theta), p.jacobian(theta)
    r, Jr = p._reduced_residual(theta), p._reduced_jacobian(theta)
    n = theta.size
    assert Jr.shape == (n + 1, n) and r.shape == (n + 1,)
    assert np.all(Jr[n] == 0.0) and np.allclose(np.tril(Jr[:n], -1), 0.0)
    # rounding of JᵀJ's Cholesky factor: ε κ² relative (κ ≤ 1e5 on that path), of a QR
    # ε κ: 1e-6 of the cost is far above both and far below any wrong term
    full0 = float(eps @ eps)
    assert abs(float(r @ r) - full0) <= 1e-9 * full0
    for _ in range(5):
        step = rng.standard_normal(n) * 1e-3 * np.maximum(np.abs(theta), 1.0)
        full = np.sum((eps + J @ step) ** 2)
        reduced = np.sum((r + Jr @ step) ** 2)
        assert abs(reduced - full) <= 1e-6 * full


def test_both_ways_of_forming_r_are_used(rng):
    from ehss.identification.pem import _COND_GRAM

    through_gram = []
    for oversampled in (False, True):
        p, theta = _problem(rng, oversampled, oe=False)
        row, lag, sign = p.layout
        G = pk.gram(p._signals_at(theta), row, lag, sign, p.k0)
        r, Jr = pk.reduce_gram(G, _COND_GRAM)
        if r.size:  # then R is JᵀJ's Cholesky factor and Rᵀq = Jᵀε
            n = G.shape[0] - 1
            R = Jr[:n]
            np.testing.assert_allclose(R.T @ R, G[:n, :n], rtol=0,
                                       atol=1e-13 * np.max(np.abs(G)))
            np.testing.assert_allclose(R.T @ r[:n], G[:n, n], rtol=0,
                                       atol=1e-13 * np.max(np.abs(G)))
        through_gram.append(r.size > 0)
    assert through_gram == [True, False]


@pytest.mark.parametrize("oe", [False, True])
def test_gram_is_the_product_of_the_formed_columns(rng, oe):
    p, theta = _problem(rng, False, oe)
    sig = p._signals_at(theta)
    row, lag, sign = p.layout
    A = pk.columns(sig, row, lag, sign, p.k0)
    G = pk.gram(sig, row, lag, sign, p.k0)
    # sums of 4000 products in another order: a few ulp of Σ|a_k b_k| each
    scale = np.sqrt(np.outer(np.sum(A * A, 0), np.sum(A * A, 0)))
    assert np.all(np.abs(G - A.T @ A) <= 1e-13 * scale)
    assert np.array_equal(A[:, -1], p.residual(theta))


def test_minpack_takes_the_same_path_on_both_forms(rng):
    p, theta = _problem(rng, False, oe=False)
    x0 = theta + 0.05 * rng.standard_normal(theta.size)
    kw = dict(method="lm", x_scale="jac", xtol=1e-10, ftol=1e-10, gtol=1e-10, max_nfev=200)
    full = least_squares(p.residual, x0, jac=p.jacobian, **kw)
    reduced = least_squares(p._reduced_residual, x0, jac=p._reduced_jacobian, **kw)
    assert full.status > 0 and reduced.status == full.status
    assert reduced.nfev == full.nfev
    # the same minimum: cost to the fit's tolerance, θ to its square root
    assert abs(reduced.cost - full.cost) <= 1e-10 * full.cost
    np.testing.assert_allclose(reduced.x, full.x, rtol=0, atol=1e-5)



def _ill_conditioned_record() -> tuple[np.ndarray, np.ndarray]:
    """A sixth-order loop (slowest pole 0.95) at 1 kHz driven by 1.5 s of 0.5–20 Hz noise,
    0.1 % output noise: an OE Jacobian that, columns scaled, has κ above _COND_GRAM."""
    from ehss.identification.model import ArmaxModel
    from ehss.signals import band_limited_random

    r = band_limited_random(band_hz=(0.5, 20.0), rms=1.0, duration_s=1.5, fs=1000.0, seed=3,
                            fade_s=0.2).values
    a = np.real(np.poly([0.95, 0.9 + 0.1j, 0.9 - 0.1j, 0.7, 0.5, 0.3]))
    true = ArmaxModel(a=a, b=[0.01, 0.02, 0.01, 0.005, 0.001, 0.0005], delay=1, dt=1e-3)
    return r, true.simulate(r) + 1e-3 * np.random.default_rng(1).standard_normal(r.size)


def ill_conditioned_fit() -> str:
    """θ of oe_pem on :func:`_ill_conditioned_record`, every float in hex."""
    from ehss.identification import oe_pem

    r, y = _ill_conditioned_record()
    m = oe_pem(r, y, nf=6, nb=5, delay=1, dt=1e-3, max_nfev=15)
    return " ".join(float(v).hex() for v in np.r_[m.a, m.b])


def test_an_ill_conditioned_fit_repeats_in_fresh_processes():
    # where the Jacobian is this ill-conditioned, scipy's C MINPACK (1.15-1.17) reads
    # past the Jacobian it is given (_Reduced.fit); fitted so, 4 of 10 processes ended
    # this fit at another optimum. Every fresh process must end at the same θ
    import pathlib
    import subprocess
    import sys

    from ehss.identification.pem import _oe_problem, _oe_starts, first_sample, rms_scale

    r, y = _ill_conditioned_record()
    us, ys = r / rms_scale(r), y / rms_scale(y)
    problem = _oe_problem(us, ys, 6, 5, 1, 0.999, first_sample(6, 5, 0, 1), [])
    assert all(problem._ill_conditioned(x) for x in _oe_starts(us, ys, 6, 5, 1, 0.999).values())
    root = pathlib.Path(__file__).resolve().parents[2]
    code = ("from tests.identification.test_pem_reduced import ill_conditioned_fit; "
            "print(ill_conditioned_fit())")
    outs = {subprocess.run([sys.executable, "-c", code], cwd=root, capture_output=True,
                           text=True, check=True).stdout for _ in range(4)}
    assert len(outs) == 1 and ill_conditioned_fit() + "\n" in outs


def test_a_reduction_that_overflows_is_not_finite_and_warns_nothing():
    # J'J too ill-conditioned (here singular) sends the reduction to a QR of [J e],
    # and a trial point whose errors overflow makes that QR not finite: the fits check
    # that in what they return, and numpy's overflow warning does not reach the user
    import warnings

    from ehss.identification.pem import _reduced

    gram = np.array([[1.0, 1.0, 0.0], [1.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    big = np.full((6, 3), 1e308)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        r, jr, by_qr = _reduced(gram, lambda: big * 10.0)
    assert by_qr and not np.all(np.isfinite(r))
    # a finite [J e] is reduced to the same R as numpy's own QR
    x = np.random.default_rng(1).standard_normal((6, 3))
    r, jr, by_qr = _reduced(gram, lambda: x)
    assert by_qr and np.allclose(np.abs(jr[:2]), np.abs(np.linalg.qr(x, mode="r")[:2, :2]),
                                 rtol=0, atol=1e-12)
