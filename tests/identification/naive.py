"""Slow, obvious numpy reference of RELS (eqs 19–22) and RML with the same safeguards.

Written from the equations, not from the kernel: numpy's own matrix products
(``P @ r``, ``r @ g``, ``np.outer``) in whatever order numpy sums them, the gain K
formed explicitly, P updated as (P − K (Pr)ᵀ)/λ and then symmetrised, C's roots from
``np.roots``, the a-posteriori residual (19) always formed directly as y − ψᵀθ̂(k).
The kernel uses other, algebraically equal forms (a square-root rank-1 update, ξ̂ from
e·λ/den), so the two agree to rounding only; the tests compare them with tolerances
derived from the problem's conditioning (see test_kernel.py).

RML (recursive maximum likelihood, the recursive prediction-error method for ARMAX,
Ljung & Söderström 1983): ψ_f(k) = ψ(k) − ĉ1 ψ_f(k−1) − … − ĉnc ψ_f(k−nc) with
ĉ = ĉ(k−1), then K = Pψ_f/(λ + ψ_fᵀPψ_f), θ̂ += K e, P = (P − K ψ_fᵀP)/λ;
e and ξ̂ use ψ as in RELS. A reset of P also zeroes the ψ_f history.
"""

from __future__ import annotations

import numpy as np

__all__ = ["naive_rels"]


def _regressor(u, y, xi, k, na, nb, nc, delay):
    """ψ(k) = [−y(k−1)..−y(k−na), u(k−d)..u(k−d−nb), ξ̂(k−1)..ξ̂(k−nc)], zeros before 0."""

    def past(x, j):
        return x[j] if j >= 0 else 0.0

    return np.array(
        [-past(y, k - i) for i in range(1, na + 1)]
        + [past(u, k - delay - i) for i in range(nb + 1)]
        + [past(xi, k - i) for i in range(1, nc + 1)]
    )


def _project(c, radius):
    """Roots of z^nc + c1 z^(nc−1) + … reflected inside the unit circle, then shrunk onto
    ``radius``; returns (new c, moved). (np.roots works in float64 only.)"""
    dtype = c.dtype
    c = c.astype(float)
    roots = np.roots(np.concatenate([[1.0], c]))
    if np.max(np.abs(roots)) < radius:
        return c.astype(dtype), False
    out = np.abs(roots) > 1
    roots[out] = 1 / np.conj(roots[out])
    big = np.abs(roots) > radius
    roots[big] = roots[big] * radius / np.abs(roots[big])
    return np.real(np.poly(roots))[1:].astype(dtype), True


def naive_rels(u, y, *, na, nb, nc, delay, lam=1.0, alpha=1e6, theta0=None,
               trace_bound=None, c_radius=0.99, alpha_c=None, method="rels",
               dtype=np.float64):
    """Return (theta, P, err, xi, counters) after running over u, y (already scaled).

    ``method`` is "rels" (eqs 19–22) or "rml" (gain and P from ψ filtered by 1/Ĉ).
    ``dtype=np.longdouble`` runs the same arithmetic in extended precision (64-bit
    mantissa on x86), a near-exact answer against which the float64 roundings of the
    kernel and of this reference are measured. ``lam`` may also be a sequence, one λ
    per sample (a forgetting switched while the estimator runs).
    """
    rml = method == "rml" and nc > 0
    n = na + nb + 1 + nc
    u = np.asarray(u, dtype=dtype)
    y = np.asarray(y, dtype=dtype)
    theta = np.zeros(n, dtype) if theta0 is None else np.array(theta0, dtype=dtype)
    alpha_c = alpha if alpha_c is None else alpha_c
    P0 = np.diag(np.r_[np.full(na + nb + 1, alpha), np.full(nc, alpha_c)]).astype(dtype)
    P = P0.copy()
    tr_max = np.trace(P0) if trace_bound is None else trace_bound
    N = len(u)
    lams = np.broadcast_to(np.asarray(lam, dtype=float), (N,))
    err = np.zeros(N, dtype)
    xi = np.zeros(N, dtype)
    resets = cproj = trscale = 0
    # RML: filt[j − 1] = ψ_f(k − j), j = 1..nc (zero before the record)
    filt = np.zeros((nc, n), dtype)
    for k in range(N):
        lam = lams[k]
        psi = _regressor(u, y, xi, k, na, nb, nc, delay)
        # e(k) = y(k) − ψᵀ(k) θ̂(k−1), the bracket of (20)
        e = y[k] - psi @ theta
        # regressor of the gain and the P update: ψ (RELS) or ψ_f = ψ/Ĉ(k−1) (RML)
        r = psi - theta[na + nb + 1:] @ filt if rml else psi
        if not (r @ P @ r >= 0 and np.isfinite(lam + r @ P @ r)):
            # P lost definiteness: back to P(0) (RML: the filter 1/Ĉ restarts)
            P = P0.copy()
            resets += 1
            if rml:
                filt[:] = 0.0
                r = psi
        Pr = P @ r
        # (21) K = P r / (λ + rᵀ P r)
        K = Pr / (lam + r @ Pr)
        # (20) θ̂(k) = θ̂(k−1) + K e
        theta = theta + K * e
        # (22) P(k) = [I − K rᵀ] P(k−1) / λ, as (P − K (P r)ᵀ)/λ, made symmetric
        P = (P - np.outer(K, Pr)) / lam
        P = 0.5 * (P + P.T)
        if lam < 1.0:
            # diagonal floor 8 n eps tr P (keeps P definite against rounding)
            P = P + 8.0 * np.finfo(float).eps * n * np.trace(P) * np.eye(n, dtype=dtype)
        if not (np.min(np.diag(P)) > 0 and np.isfinite(np.trace(P))):
            P = P0.copy()
            resets += 1
            if rml:
                filt[:] = 0.0
                r = np.zeros(n, dtype)
        elif np.trace(P) > tr_max:
            P = P * (tr_max / np.trace(P))
            trscale += 1
        if nc > 0:
            theta[na + nb + 1:], moved = _project(theta[na + nb + 1:], c_radius)
            cproj += moved
        # (19) ξ̂(k) = y(k) − ψᵀ(k) θ̂(k)
        xi[k] = y[k] - psi @ theta
        err[k] = e
        if rml:
            filt = np.vstack([r, filt[:-1]])
    return theta, P, err, xi, {"resets": resets, "c_projections": cproj,
                               "trace_scalings": trscale}
