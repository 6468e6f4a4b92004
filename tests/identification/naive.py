"""Slow, obvious numpy reference of RELS (eqs 19–22) and RML with the same safeguards.

One numpy expression per equation, no state buffer, no vectorisation tricks: the
compiled kernel in ``ehss.identification._kernels`` must agree with this to 1e-12.
The expressions round as the kernel does (P − w wᵀ with w = g √(1/den), sums left to
right, or in the kernel's pairwise tree where its 4-wide path forms them: ŷ, ψᵀPψ
and tr P for n ≤ 32), so that the agreement tests the algorithm and not the luck of
two rounding patterns: with P(0) = 10⁶ I, early downdates cancel six digits, and any
other rounding of them shows up near 1e-10.

RML (recursive maximum likelihood, the recursive prediction-error method for ARMAX,
Ljung & Söderström 1983): ψ_f(k) = ψ(k) − ĉ1 ψ_f(k−1) − … − ĉnc ψ_f(k−nc) with
ĉ = ĉ(k−1), then K = Pψ_f/(λ + ψ_fᵀPψ_f), θ̂ += K e, P = (P − Pψ_f ψ_fᵀP/den)/λ;
e and ξ̂ use ψ as in RELS. A reset of P also zeroes the ψ_f history.
"""

from __future__ import annotations

import numpy as np

__all__ = ["naive_rels"]


def naive_rels(u, y, *, na, nb, nc, delay, lam=1.0, alpha=1e6, theta0=None,
               trace_bound=None, c_radius=0.99, alpha_c=None, method="rels"):
    """Return (theta, P, err, xi, counters) after running over u, y (already scaled).

    ``method`` is "rels" (eqs 19–22) or "rml" (gain and P from ψ filtered by 1/Ĉ).
    """
    rml = method == "rml" and nc > 0
    n = na + nb + 1 + nc
    theta = np.zeros(n) if theta0 is None else np.array(theta0, dtype=float)
    alpha_c = alpha if alpha_c is None else alpha_c
    P0 = np.diag(np.r_[np.full(na + nb + 1, alpha), np.full(nc, alpha_c)])
    P = P0.copy()
    tr_max = np.trace(P0) if trace_bound is None else trace_bound
    N = len(u)
    err = np.zeros(N)
    xi = np.zeros(N)
    resets = cproj = trscale = 0
    # RML: hist[j − 1] = ψ_f(k − j), j = 1..nc (zero before the record)
    hist = [np.zeros(n) for _ in range(nc)]

    def past(x, k):
        return x[k] if k >= 0 else 0.0

    def dot(p, q):
        # left-to-right summation, the order the kernel uses (np.dot/BLAS reorders)
        return np.cumsum(p * q)[-1]

    def matvec(M, v):
        return np.cumsum(M * v[None, :], axis=1)[:, -1]

    vector_path = (n + 3) // 4 * 4 <= 32  # the kernel's 4-wide path (SIMD_MAX)

    def tree(values):
        # pairwise, level by level: (v0 + v1), (v2 + v3), …; an odd last one moves up
        while len(values) > 1:
            values = [values[i] + values[i + 1] if i + 1 < len(values) else values[i]
                      for i in range(0, len(values), 2)]
        return values[0]

    def tree_dot(p, q):
        # 4-wide products added in the pairwise tree, then lanes (l0 + l1) + (l2 + l3)
        if not vector_path:
            return dot(p, q)
        m = (n + 3) // 4 * 4
        prod = np.zeros(m)
        prod[:n] = p * q
        v = tree([prod[i:i + 4] for i in range(0, m, 4)])
        return (v[0] + v[1]) + (v[2] + v[3])

    def trace(d):
        return tree(list(d)) if vector_path else np.cumsum(d)[-1]

    for k in range(N):
        psi = np.array(
            [-past(y, k - i) for i in range(1, na + 1)]
            + [past(u, k - delay - i) for i in range(nb + 1)]
            + [past(xi, k - i) for i in range(1, nc + 1)]
        )
        e = y[k] - (dot(psi, theta) if rml else tree_dot(psi, theta))
        # regressor of the gain and the P update: ψ (RELS) or ψ_f = ψ/Ĉ(k−1) (RML)
        r = psi
        if rml:
            c_prev = theta[na + nb + 1:]
            r = psi.copy()
            for j in range(nc):
                r = r - c_prev[j] * hist[j]
        g = matvec(P, r)
        s = dot(r, g) if rml else tree_dot(r, g)
        den = lam + s
        if not (s >= 0 and np.isfinite(den)):  # ψᵀPψ < 0: P is not definite
            P = P0.copy()
            resets += 1
            if rml:  # the filter 1/Ĉ restarts from rest
                hist = [np.zeros(n) for _ in range(nc)]
                r = psi.copy()
            g = matvec(P, r)
            den = lam + dot(r, g)
        inv_den = 1.0 / den
        # (21) K = P r / den; (20) theta += K e
        theta = theta + (g * inv_den) * e
        # (22) in symmetric form (P − g gᵀ/den)/λ = P/λ − w wᵀ, w = g √(1/(den λ))
        w = g * np.sqrt(inv_den * (1.0 / lam))
        P = P * (1.0 / lam) - np.outer(w, w)
        d = np.diag(P).copy()
        tr = trace(d)
        if lam < 1.0:
            # diagonal floor δ = 8 n eps tr P (keeps P definite against downdate rounding)
            delta = 8.0 * np.finfo(float).eps * n * tr
            P = P + delta * np.eye(n)
            tr = tr + n * delta
        if not (d.min() > 0 and np.isfinite(tr)):
            P = P0.copy()
            resets += 1
            if rml:  # the filter 1/Ĉ restarts from rest (ψ_f(k) dropped too)
                hist = [np.zeros(n) for _ in range(nc)]
                r = np.zeros(n)
        elif tr > tr_max:
            P = P * (tr_max / tr)
            trscale += 1
        projected = False
        if nc > 0:
            c = theta[na + nb + 1:]
            roots = np.roots(np.concatenate([[1.0], c]))
            if np.max(np.abs(roots)) >= c_radius:
                out = np.abs(roots) > 1
                roots[out] = 1 / np.conj(roots[out])
                big = np.abs(roots) > c_radius
                roots[big] = roots[big] * c_radius / np.abs(roots[big])
                theta[na + nb + 1:] = np.real(np.poly(roots))[1:]
                cproj += 1
                projected = True
        # (19) ξ̂ = y − ψᵀθ(k); without projection this is algebraically e λ/den (RELS)
        # or e − (ψᵀg/den) e (RML), the forms the kernel uses (bit-for-bit agreement
        # needs the same rounding)
        if projected:
            xi[k] = y[k] - dot(psi, theta)
        elif rml:
            xi[k] = e - (dot(psi, g) * inv_den) * e
        else:
            xi[k] = e * (lam * inv_den)
        err[k] = e
        if rml:
            hist = [r, *hist[:-1]]
    return theta, P, err, xi, {"resets": resets, "c_projections": cproj,
                               "trace_scalings": trscale}
