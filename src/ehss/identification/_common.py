"""What every estimator of the identification package shares: checks, scaling, regressors.

The argument checks of the orders and settings, the RMS scaling of a record (and the
factor that carries θ between scaled and physical units), the regression matrix
ψ(k)ᵀ = [−y(k−1)..−y(k−na), u(k−d)..u(k−d−nb), e(k−1)..e(k−nc)] of the paper's eq. (19),
the one-step prediction errors ε = (A y − q^-d B u)/C of a θ, and the reflection of a
monic polynomial's roots into a circle. Batch (least squares, ELS, PEM) and recursive
(RELS, RML) estimators use these one definitions.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy.signal import lfilter

from ehss._checks import as_record, is_integer, is_real
from ehss.errors import DataError, ParameterError

__all__ = [
    "order_arg",
    "real_arg",
    "radius_arg",
    "check_settings",
    "check_batch",
    "rms_scale",
    "theta_scale",
    "regression_matrix",
    "prediction_errors",
    "stabilise",
    "first_sample",
]


def order_arg(name: str, value: Any, minimum: int) -> int:
    """``value`` as an int ≥ ``minimum`` (ParameterError naming ``name`` otherwise)."""
    if not is_integer(value):
        raise ParameterError(f"{name}={value!r} must be an integer >= {minimum}")
    if value < minimum:
        raise ParameterError(f"{name}={value!r} must be an integer >= {minimum}")
    return int(value)


def real_arg(name: str, value: Any) -> float:
    """``value`` as a finite float (ParameterError naming ``name`` otherwise)."""
    if not is_real(value):
        raise ParameterError(f"{name}={value!r} must be a real number")
    value = float(value)
    if not math.isfinite(value):
        raise ParameterError(f"{name}={value!r} must be finite")
    return value


def radius_arg(name: str, value: Any) -> float:
    """A root radius in (0, 1)."""
    r = real_arg(name, value)
    if not 0.0 < r < 1.0:
        raise ParameterError(f"{name}={value!r} must be in (0, 1)")
    return r


def check_settings(
    na: Any, nb: Any, nc: Any, delay: Any, forgetting: Any, p0: Any, dt: Any
) -> tuple[int, int, int, int, float, float, float]:
    """Orders (na ≥ 1, nb ≥ 0, nc ≥ 0, delay ≥ 0), λ in (0, 1], α > 0 and dt > 0 (s)."""
    na = order_arg("na", na, 1)
    nb = order_arg("nb", nb, 0)
    nc = order_arg("nc", nc, 0)
    delay = order_arg("delay", delay, 0)
    lam = real_arg("forgetting", forgetting)
    if not 0.0 < lam <= 1.0:
        raise ParameterError(f"forgetting={forgetting!r} must be in (0, 1]")
    alpha = real_arg("p0", p0)
    if alpha <= 0:
        raise ParameterError(f"p0={p0!r} must be > 0")
    dt = real_arg("dt", dt)
    if dt <= 0:
        raise ParameterError(f"dt={dt!r} must be > 0 (seconds)")
    return na, nb, nc, delay, lam, alpha, dt


def first_sample(na: int, nb: int, nc: int, delay: int) -> int:
    """k0 = max(na, nb + d, nc): the first sample whose regressors are all measured."""
    return max(na, nb + delay, nc)


def check_batch(u: Any, y: Any, na: Any, nb: Any, nc: Any, delay: Any, dt: Any):
    """Record and orders of a batch estimator; DataError when the record is too short.

    Returns (u, y, na, nb, nc, delay, dt) with u, y contiguous float64.
    """
    na, nb, nc, delay, _, _, dt = check_settings(na, nb, nc, delay, 1.0, 1.0, dt)
    u, y = as_record(u, y)
    n = na + nb + 1 + nc
    need = first_sample(na, nb, nc, delay) + n + 1
    if u.size < need:
        raise DataError(
            f"{u.size} samples are too few for na={na}, nb={nb}, nc={nc}, delay={delay}: "
            f"need at least {need}"
        )
    return u, y, na, nb, nc, delay, dt


def rms_scale(x: np.ndarray) -> float:
    """RMS of x, formed as max|x| · RMS(x / max|x|) so that it neither overflows nor
    underflows for data of any float64 magnitude (1 for an all-zero record)."""
    peak = float(np.max(np.abs(x))) if x.size else 0.0
    if not (peak > 0.0 and math.isfinite(peak)):
        return 1.0
    return peak * float(np.sqrt(np.mean(np.square(x / peak))))


def theta_scale(na: int, nb: int, nc: int, u_scale: float, y_scale: float) -> np.ndarray:
    """Factor D with θ_physical = D θ_scaled (only the b-part changes: b = b_s s_y/s_u)."""
    dvec = np.ones(na + nb + 1 + nc)
    with np.errstate(over="ignore", under="ignore"):  # the caller checks the product
        dvec[na : na + nb + 1] = y_scale / u_scale
    return dvec


def regression_matrix(
    u: np.ndarray, y: np.ndarray, e: np.ndarray | None, na: int, nb: int, nc: int, delay: int
) -> tuple[np.ndarray, np.ndarray, int]:
    """Rows ψ(k)ᵀ = [−y(k−1)..−y(k−na), u(k−d)..u(k−d−nb), e(k−1)..e(k−nc)], k ≥ k0.

    Returns (Phi, target y[k0:], k0) with k0 = max(na, nb + delay, nc) so that every
    regressor uses measured samples only.
    """
    N = y.size
    k0 = first_sample(na, nb, nc, delay)
    cols = [-y[k0 - i : N - i] for i in range(1, na + 1)]
    cols += [u[k0 - delay - i : N - delay - i] for i in range(nb + 1)]
    if nc:
        cols += [e[k0 - i : N - i] for i in range(1, nc + 1)]
    return np.column_stack(cols), y[k0:], k0


def prediction_errors(theta: np.ndarray, u: np.ndarray, y: np.ndarray, na: int, nb: int,
                      nc: int, delay: int) -> np.ndarray:
    """ε = (A y − q^-d B u) / C for every sample (one-step prediction errors, at rest
    before the record)."""
    a = np.concatenate([[1.0], theta[:na]])
    bd = np.concatenate([np.zeros(delay), theta[na : na + nb + 1]])
    c = np.concatenate([[1.0], theta[na + nb + 1 :]])
    v = lfilter(a, [1.0], y) - lfilter(bd, [1.0], u)
    return lfilter([1.0], c, v)


def stabilise(c: np.ndarray, radius: float = 0.99) -> np.ndarray:
    """Reflect the roots of [1, c...] outside the unit circle into it and shrink those
    beyond ``radius`` onto it (as RELS keeps C); c itself when already inside."""
    if c.size == 0:
        return c
    r = np.roots(np.concatenate([[1.0], c]))
    if r.size == 0 or np.max(np.abs(r)) < radius:
        return c
    out = np.abs(r) > 1
    r[out] = 1 / np.conj(r[out])
    big = np.abs(r) > radius
    r[big] *= radius / np.abs(r[big])
    return np.real(np.poly(r))[1:]
