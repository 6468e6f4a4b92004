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
def _inverse(x: np.ndarray, den: np.ndarray) -> np.ndarray:
    """x filtered by 1/D, D = 1 + den[0] q^-1 + … (at rest before x[0])."""
    n = den.size
    out = np.empty(x.size)
    for k in range(x.size):
        s = x[k]
        for i in range(1, min(n, k) + 1):
            s -= den[i - 1] * out[k - i]
        out[k] = s
    return out


@njit(cache=True, nogil=True)
def armax_errors(theta: np.ndarray, us: np.ndarray, ys: np.ndarray, na: int, nb: int,
                 nc: int, delay: int) -> np.ndarray:
    """ε(k) = (A y − q^-d B u)(k) − c1 ε(k−1) − … − c_nc ε(k−nc) for every k."""
    nab = na + nb + 1
    eps = np.empty(ys.size)
    for k in range(ys.size):
        v = ys[k]
        for i in range(1, min(na, k) + 1):
            v += theta[i - 1] * ys[k - i]
        for j in range(nb + 1):
            m = k - delay - j
            if m >= 0:
                v -= theta[na + j] * us[m]
        for i in range(1, min(nc, k) + 1):
            v -= theta[nab + i - 1] * eps[k - i]
        eps[k] = v
    return eps


@njit(cache=True, nogil=True)
def armax_jacobian(theta: np.ndarray, us: np.ndarray, ys: np.ndarray, eps: np.ndarray,
                   na: int, nb: int, nc: int, delay: int, k0: int) -> np.ndarray:
    """∂ε(k)/∂θ for k ≥ k0 (k0 ≥ max(na, nb + d, nc)), rows k − k0.

    ∂ε/∂a_i = y(k−i)/C, ∂ε/∂b_j = −u(k−d−j)/C, ∂ε/∂c_i = −ε(k−i)/C.
    """
    nab = na + nb + 1
    c = theta[nab:]
    wy, wu, we = _inverse(ys, c), _inverse(us, c), _inverse(eps, c)
    J = np.empty((ys.size - k0, nab + nc))
    for r in range(ys.size - k0):
        k = r + k0
        for i in range(1, na + 1):
            J[r, i - 1] = wy[k - i]
        for j in range(nb + 1):
            J[r, na + j] = -wu[k - delay - j]
        for i in range(1, nc + 1):
            J[r, nab + i - 1] = -we[k - i]
    return J


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
def oe_jacobian(theta: np.ndarray, us: np.ndarray, yhat: np.ndarray, nf: int, nb: int,
                delay: int, k0: int) -> np.ndarray:
    """∂ε(k)/∂θ of ε = y − ŷ for k ≥ k0: ∂ε/∂f_i = ŷ(k−i)/F, ∂ε/∂b_j = −u(k−d−j)/F."""
    f = theta[:nf]
    wy, wu = _inverse(yhat, f), _inverse(us, f)
    J = np.empty((us.size - k0, nf + nb + 1))
    for r in range(us.size - k0):
        k = r + k0
        for i in range(1, nf + 1):
            J[r, i - 1] = wy[k - i]
        for j in range(nb + 1):
            J[r, nf + j] = -wu[k - delay - j]
    return J
