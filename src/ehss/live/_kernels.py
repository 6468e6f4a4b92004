"""Compiled kernels of live change detection (no validation: :mod:`ehss.live.detect`
checks and converts).

Symbols: ``a`` = [1, a1, …, a_na], ``bd`` = [0…0 (d zeros), b0, …, b_nb], ``c`` =
[1, c1, …, c_nc], all padded with zeros to one length L + 1; ``hy``, ``hu``, ``he``
the last L values of y, u and ε, newest first.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["prediction_errors"]


@njit(cache=True)
def prediction_errors(a: np.ndarray, bd: np.ndarray, c: np.ndarray, u: np.ndarray,
                      y: np.ndarray, hy: np.ndarray, hu: np.ndarray, he: np.ndarray,
                      out: np.ndarray) -> None:
    """ε(t) of an ARMAX model over ``u``, ``y`` into ``out``, the histories updated.

    C(q) ε(t) = A(q) y(t) − q^{-d} B(q) u(t), i.e. (eq (19) of the paper, solved for
    the residual)
    ε(t) = Σ_{i≥0} a_i y(t−i) − Σ_{j≥0} bd_j u(t−j) − Σ_{k≥1} c_k ε(t−k).
    """
    n_hist = hy.size
    for t in range(u.size):
        e = a[0] * y[t] - bd[0] * u[t]
        for i in range(n_hist):
            e += a[i + 1] * hy[i] - bd[i + 1] * hu[i] - c[i + 1] * he[i]
        out[t] = e
        # shift the histories: newest first
        for i in range(n_hist - 1, 0, -1):
            hy[i] = hy[i - 1]
            hu[i] = hu[i - 1]
            he[i] = he[i - 1]
        if n_hist:
            hy[0] = y[t]
            hu[0] = u[t]
            he[0] = e
