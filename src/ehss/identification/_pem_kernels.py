"""Compiled prediction errors and their Jacobians for the PEM fits (:mod:`.pem`).

Each kernel takes plain arrays and the orders, starts the predictor at rest before the
first sample (zero initial conditions) and releases the GIL (``nogil=True``), so that
candidate fits can run on several threads. The Jacobians use that filtering commutes
with a delay: the column of ∂ε/∂a_i is y(k − i) filtered by 1/C, i.e. the one signal
y/C delayed by i samples, so each Jacobian costs three (ARMAX) or two (OE) recursive
filters of the record instead of one per parameter (Ljung, *System Identification*,
2nd ed., 1999, §10.2).

θ layouts: ARMAX [a1..a_na, b0..b_nb, c1..c_nc]; OE [f1..f_nf, b0..b_nb].
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = [
    "roots_inside",
    "armax_errors",
    "armax_jacobian",
    "armax_filtered",
    "els_layout",
    "oe_simulate",
    "oe_jacobian",
]


@njit(cache=True, nogil=True)
def roots_inside(p: np.ndarray, radius: float) -> bool:
    """True if every root of z^n + p1 z^(n−1) + … lies strictly inside ``radius``.

    Schur–Cohn: the roots scaled by 1/radius are those of [1, p1/r, p2/r², …]; the
    step-down (Levinson) recursion on it finds its reflection coefficients k, and all
    |k| < 1 iff all its roots are inside the unit circle. O(n²).
    """
    n = p.size
    a = np.empty(n + 1)
    a[0] = 1.0
    scale = 1.0
    for i in range(n):
        scale /= radius
        a[i + 1] = p[i] * scale
    m = n
    while m > 0:
        k = a[m] / a[0]
        if not abs(k) < 1.0:
            return False
        new = np.empty(m)
        for i in range(m):
            new[i] = (a[i] - k * a[m - i]) / (1.0 - k * k)
        a = new
        m -= 1
    return True


@njit(cache=True, nogil=True)
def _inverse(x: np.ndarray, den: np.ndarray, out: np.ndarray) -> None:
    """out = x filtered by 1/D, D = 1 + den[0] q^-1 + … (at rest before x[0])."""
    n = den.size
    for k in range(min(n, x.size)):
        s = x[k]
        for i in range(1, k + 1):
            s -= den[i - 1] * out[k - i]
        out[k] = s
    for k in range(n, x.size):
        s = x[k]
        past = out[k - n : k]  # past[n − i] = out[k − i]
        for i in range(1, n + 1):
            s -= den[i - 1] * past[n - i]
        out[k] = s


@njit(cache=True, nogil=True, inline="always")
def _error_at(theta: np.ndarray, us: np.ndarray, ys: np.ndarray, eps: np.ndarray, k: int,
              na: int, nb: int, nc: int, delay: int) -> float:
    """ε(k) = (A y − q^-d B u)(k) − c1 ε(k−1) − … − c_nc ε(k−nc), given ε before k."""
    nab = na + nb + 1
    v = ys[k]
    for i in range(1, min(na, k) + 1):
        v += theta[i - 1] * ys[k - i]
    for j in range(nb + 1):
        m = k - delay - j
        if m >= 0:
            v -= theta[na + j] * us[m]
    for i in range(1, min(nc, k) + 1):
        v -= theta[nab + i - 1] * eps[k - i]
    return v


@njit(cache=True, nogil=True)
def armax_errors(theta: np.ndarray, us: np.ndarray, ys: np.ndarray, na: int, nb: int,
                 nc: int, delay: int) -> np.ndarray:
    """ε(k) = (A y − q^-d B u)(k) − c1 ε(k−1) − … − c_nc ε(k−nc) for every k."""
    eps = np.empty(ys.size)
    for k in range(ys.size):
        eps[k] = _error_at(theta, us, ys, eps, k, na, nb, nc, delay)
    return eps


@njit(cache=True, nogil=True)
def armax_signals(theta: np.ndarray, us: np.ndarray, ys: np.ndarray, eps: np.ndarray,
                  na: int, nb: int, nc: int) -> np.ndarray:
    """Rows y/C, u/C, ε/C and ε: what the ARMAX Jacobian's columns are delayed copies of,
    and the residual."""
    c = theta[na + nb + 1 : na + nb + 1 + nc]
    out = np.empty((4, ys.size))
    _inverse(ys, c, out[0])
    _inverse(us, c, out[1])
    _inverse(eps, c, out[2])
    out[3] = eps
    return out


@njit(cache=True, nogil=True)
def armax_filtered(theta: np.ndarray, us: np.ndarray, ys: np.ndarray, na: int, nb: int,
                   nc: int, delay: int) -> np.ndarray:
    """:func:`armax_signals` of :func:`armax_errors`' ε, in one pass over the record.

    The four recursions (ε, y/C, u/C, ε/C) are independent from one sample to the next
    but each is a chain of dependent products; run side by side in one loop, the
    processor overlaps them. Each is summed in the same order as in those two kernels,
    so the rows are the same to the last bit.
    """
    nab = na + nb + 1
    c = theta[nab : nab + nc]
    out = np.empty((4, ys.size))
    yc, uc, ec, eps = out[0], out[1], out[2], out[3]
    for k in range(ys.size):
        se = eps[k] = _error_at(theta, us, ys, eps, k, na, nb, nc, delay)
        sy, su = ys[k], us[k]
        for i in range(1, min(nc, k) + 1):
            sy -= c[i - 1] * yc[k - i]
            su -= c[i - 1] * uc[k - i]
            se -= c[i - 1] * ec[k - i]
        yc[k], uc[k], ec[k] = sy, su, se
    return out


@njit(cache=True, nogil=True)
def _layout(na: int, nb: int, nc: int, delay: int, residual_row: int) -> tuple:
    """(row, lag, sign) of the columns of [J | ε] for θ = [a, b, c]: the lags 1..na of
    row 0, −(lags d..d+nb of row 1), −(lags 1..nc of row 2), then ``residual_row``."""
    n = na + nb + 1 + nc
    row = np.empty(n + 1, dtype=np.int64)
    lag = np.empty(n + 1, dtype=np.int64)
    sign = np.empty(n + 1)
    for i in range(na):
        row[i], lag[i], sign[i] = 0, i + 1, 1.0
    for j in range(nb + 1):
        row[na + j], lag[na + j], sign[na + j] = 1, delay + j, -1.0
    for i in range(nc):
        row[na + nb + 1 + i], lag[na + nb + 1 + i], sign[na + nb + 1 + i] = 2, i + 1, -1.0
    row[n], lag[n], sign[n] = residual_row, 0, 1.0
    return row, lag, sign


@njit(cache=True, nogil=True)
def armax_layout(na: int, nb: int, nc: int, delay: int) -> tuple:
    """(row, lag, sign) of each column of [J | ε] in :func:`armax_signals`' rows:
    ∂ε/∂a_i = y(k−i)/C, ∂ε/∂b_j = −u(k−d−j)/C, ∂ε/∂c_i = −ε(k−i)/C, then ε(k)."""
    return _layout(na, nb, nc, delay, 3)


@njit(cache=True, nogil=True)
def els_layout(na: int, nb: int, nc: int, delay: int) -> tuple:
    """(row, lag, sign) of the columns of [−Φ t] in the rows y, u, e: the regression of
    extended least squares (y(k) = ψ(k)ᵀθ + e(k), ψ(k)ᵀ = [−y(k−1).., u(k−d).., e(k−1)..])
    is that of the ARMAX Jacobian with y, u, e in place of y/C, u/C, ε/C and target y(k)."""
    return _layout(na, nb, nc, delay, 0)


@njit(cache=True, nogil=True)
def columns(signals: np.ndarray, row: np.ndarray, lag: np.ndarray, sign: np.ndarray,
            k0: int) -> np.ndarray:
    """A[k − k0, c] = sign[c] · signals[row[c], k − lag[c]] for k = k0 … N − 1."""
    m = signals.shape[1] - k0
    A = np.empty((m, row.size))
    for c in range(row.size):
        src = signals[row[c], k0 - lag[c] : k0 - lag[c] + m]
        for r in range(m):
            A[r, c] = sign[c] * src[r]
    return A


@njit(cache=True, nogil=True, fastmath={"reassoc", "contract"})
def _dot(x: np.ndarray, y: np.ndarray) -> float:
    """Σ x_k y_k (reassociated: LLVM sums in vector lanes)."""
    s = 0.0
    for k in range(x.size):
        s += x[k] * y[k]
    return s


@njit(cache=True, nogil=True)
def gram(signals: np.ndarray, row: np.ndarray, lag: np.ndarray, sign: np.ndarray,
         k0: int) -> np.ndarray:
    """AᵀA of :func:`columns`' A without forming A.

    An entry is a dot product of two delayed rows x, y of ``signals``; when the columns
    before both (a − 1, b − 1) are the same rows one lag less, the entry is theirs with
    the window moved by a sample: Σ_{k=k0}^{N−1} x(k−l−1) y(k−m−1) = Σ_{k=k0}^{N−1}
    x(k−l) y(k−m) + x(k0−l−1) y(k0−m−1) − x(N−l−1) y(N−m−1). Only the entries on the
    first column of a block of lags are summed in full.
    """
    n = row.size
    m = signals.shape[1] - k0
    G = np.empty((n, n))
    for a in range(n):  # x(k0 − l) … x(N − l): one more than the window where l ≥ 1
        xa = signals[row[a], k0 - lag[a] : k0 - lag[a] + m + 1]
        for b in range(a, n):
            xb = signals[row[b], k0 - lag[b] : k0 - lag[b] + m + 1]
            if a > 0 and _next_lag(row, lag, a) and _next_lag(row, lag, b):
                s = sign[a - 1] * sign[b - 1] * G[a - 1, b - 1]
                G[a, b] = sign[a] * sign[b] * (s + xa[0] * xb[0] - xa[m] * xb[m])
            else:
                G[a, b] = sign[a] * sign[b] * _dot(xa[:m], xb[:m])
            G[b, a] = G[a, b]
    return G


@njit(cache=True, nogil=True)
def _next_lag(row: np.ndarray, lag: np.ndarray, c: int) -> bool:
    """Column c is column c − 1's row one lag later."""
    return c > 0 and row[c] == row[c - 1] and lag[c] == lag[c - 1] + 1


@njit(cache=True, nogil=True)
def armax_jacobian(theta: np.ndarray, us: np.ndarray, ys: np.ndarray, eps: np.ndarray,
                   na: int, nb: int, nc: int, delay: int, k0: int) -> np.ndarray:
    """∂ε(k)/∂θ for k ≥ k0 (k0 ≥ max(na, nb + d, nc)), rows k − k0."""
    row, lag, sign = armax_layout(na, nb, nc, delay)
    n = row.size - 1
    return columns(armax_signals(theta, us, ys, eps, na, nb, nc), row[:n], lag[:n],
                   sign[:n], k0)


@njit(cache=True, nogil=True)
def oe_simulate(theta: np.ndarray, us: np.ndarray, nf: int, nb: int,
                delay: int) -> np.ndarray:
    """ŷ = q^-d B/F u: ŷ(k) = Σ b_j u(k−d−j) − f1 ŷ(k−1) − … − f_nf ŷ(k−nf)."""
    yhat = np.empty(us.size)
    for k in range(us.size):
        v = 0.0
        for j in range(nb + 1):
            m = k - delay - j
            if m >= 0:
                v += theta[nf + j] * us[m]
        for i in range(1, min(nf, k) + 1):
            v -= theta[i - 1] * yhat[k - i]
        yhat[k] = v
    return yhat


@njit(cache=True, nogil=True)
def oe_signals(theta: np.ndarray, us: np.ndarray, yhat: np.ndarray, eps: np.ndarray,
               nf: int) -> np.ndarray:
    """Rows ŷ/F, u/F and ε = y − ŷ: what the OE Jacobian's columns are delayed copies
    of, and the residual."""
    out = np.empty((3, us.size))
    _inverse(yhat, theta[:nf], out[0])
    _inverse(us, theta[:nf], out[1])
    out[2] = eps
    return out


@njit(cache=True, nogil=True)
def oe_layout(nf: int, nb: int, delay: int) -> tuple:
    """(row, lag, sign) of each column of [J | ε] in :func:`oe_signals`' rows:
    ∂ε/∂f_i = ŷ(k−i)/F, ∂ε/∂b_j = −u(k−d−j)/F, then ε(k) = y(k) − ŷ(k)."""
    return _layout(nf, nb, 0, delay, 2)


@njit(cache=True, nogil=True)
def oe_jacobian(theta: np.ndarray, us: np.ndarray, yhat: np.ndarray, nf: int, nb: int,
                delay: int, k0: int) -> np.ndarray:
    """∂ε(k)/∂θ of ε = y − ŷ for k ≥ k0: ∂ε/∂f_i = ŷ(k−i)/F, ∂ε/∂b_j = −u(k−d−j)/F."""
    row, lag, sign = oe_layout(nf, nb, delay)
    n = row.size - 1
    # the residual row (here a stand-in) is not among J's columns
    return columns(oe_signals(theta, us, yhat, yhat, nf), row[:n], lag[:n], sign[:n], k0)


@njit(cache=True, nogil=True)
def reduce_gram(G: np.ndarray, max_cond: float) -> tuple[np.ndarray, np.ndarray]:
    """The least-squares problem of [J ε] reduced to n + 1 rows, from G = [J ε]ᵀ[J ε].

    Returns the residual [q; ρ] and Jacobian [R; 0] with RᵀR = JᵀJ (R upper triangular),
    Rᵀq = Jᵀε and ρ² = εᵀε − qᵀq, so that ‖q + R p‖² + ρ² = ‖ε + J p‖² for every p; or
    two empty arrays when J, its columns scaled to unit norm, has a condition number
    above ``max_cond`` (R is then to come from a QR of [J ε]).
    """
    n = G.shape[0] - 1
    empty = (np.empty(0), np.empty((0, 0)))
    d = np.sqrt(np.diag(G)[:n])
    if not np.all(d > 0.0):
        return empty
    Gs = G[:n, :n] / np.outer(d, d)
    w = np.linalg.eigvalsh(Gs)  # κ(J_s)² = κ(J_sᵀ J_s)
    if not w[0] > w[n - 1] / (max_cond * max_cond):
        return empty
    R = np.linalg.cholesky(Gs).T * d  # J = J_s D: R = R_s D
    q = np.empty(n)
    for i in range(n):  # Rᵀ q = Jᵀε, Rᵀ lower triangular
        s = G[i, n]
        for j in range(i):
            s -= R[j, i] * q[j]
        q[i] = s / R[i, i]
    r = np.empty(n + 1)
    r[:n] = q
    r[n] = np.sqrt(max(G[n, n] - np.dot(q, q), 0.0))
    Jr = np.zeros((n + 1, n))
    Jr[:n] = R
    return r, Jr
