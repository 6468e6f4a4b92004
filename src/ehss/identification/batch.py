"""Batch references for RELS: ARX least squares and ARMAX extended least squares / PEM.

These are the slow-but-sure estimators RELS is checked against (with λ = 1 and a large
P(0), RELS approaches :func:`arx_ls` on ARX data) and the workhorse of order selection.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy.signal import lfilter

from ehss.errors import DataError, IdentificationError
from ehss.identification.model import ArmaxModel
from ehss.identification.rels import _check_settings, _order, _real, check_record

__all__ = ["arx_ls", "armax_els", "els_theta", "regression_matrix"]


def regression_matrix(
    u: np.ndarray, y: np.ndarray, e: np.ndarray | None, na: int, nb: int, nc: int, delay: int
) -> tuple[np.ndarray, np.ndarray, int]:
    """Rows ψ(k)ᵀ = [−y(k−1)..−y(k−na), u(k−d)..u(k−d−nb), e(k−1)..e(k−nc)], k ≥ k0.

    Returns (Phi, target y[k0:], k0) with k0 = max(na, nb + delay, nc) so that every
    regressor uses measured samples only.
    """
    N = y.size
    k0 = max(na, nb + delay, nc)
    cols = [-y[k0 - i : N - i] for i in range(1, na + 1)]
    cols += [u[k0 - delay - i : N - delay - i] for i in range(nb + 1)]
    if nc:
        cols += [e[k0 - i : N - i] for i in range(1, nc + 1)]
    return np.column_stack(cols), y[k0:], k0


def _validate(u: Any, y: Any, na: Any, nb: Any, nc: Any, delay: Any, dt: Any):
    na, nb, nc, delay, _, _, dt = _check_settings(na, nb, nc, delay, 1.0, 1.0, dt)
    u, y = check_record(u, y)
    n = na + nb + 1 + nc
    need = max(na, nb + delay, nc) + n + 1
    if u.size < need:
        raise DataError(
            f"{u.size} samples are too few for na={na}, nb={nb}, nc={nc}, delay={delay}: "
            f"need at least {need}"
        )
    return u, y, na, nb, nc, delay, dt


def _model(theta, na, nb, nc, delay, dt, nv, cov, meta) -> ArmaxModel:
    return ArmaxModel(
        a=np.concatenate([[1.0], theta[:na]]), b=theta[na : na + nb + 1],
        c=np.concatenate([[1.0], theta[na + nb + 1 :]]), delay=delay, dt=dt,
        noise_variance=nv, covariance=cov, meta=meta,
    )


def arx_ls(u: Any, y: Any, *, na: int, nb: int, delay: int = 1, dt: float = 1.0) -> ArmaxModel:
    """ARX model A y = q^-d B u + ξ by linear least squares (``numpy.linalg.lstsq``).

    The first max(na, nb + d) samples only feed regressors. ``covariance`` is
    σ² (ΦᵀΦ)⁻¹ with σ² the residual variance (dof-corrected).
    """
    u, y, na, nb, _, delay, dt = _validate(u, y, na, nb, 0, delay, dt)
    phi, t, _ = regression_matrix(u, y, None, na, nb, 0, delay)
    theta, *_ = np.linalg.lstsq(phi, t, rcond=None)
    res = t - phi @ theta
    dof = max(t.size - theta.size, 1)
    nv = float(res @ res / dof)
    cov = nv * np.linalg.pinv(phi.T @ phi)
    meta = {"method": "arx_ls", "n_samples": int(u.size)}
    return _model(theta, na, nb, 0, delay, dt, nv, cov, meta)


def _stabilise(c: np.ndarray, radius: float = 0.99) -> np.ndarray:
    """Reflect/shrink the roots of [1, c...] inside ``radius`` (as in RELS)."""
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


def _pred_errors(theta, u, y, na, nb, nc, delay) -> np.ndarray:
    """ε = (A y − q^-d B u) / C (one-step prediction errors, zero initial conditions)."""
    a = np.concatenate([[1.0], theta[:na]])
    bd = np.concatenate([np.zeros(delay), theta[na : na + nb + 1]])
    c = np.concatenate([[1.0], theta[na + nb + 1 :]])
    v = lfilter(a, [1.0], y) - lfilter(bd, [1.0], u)
    return lfilter([1.0], c, v)


def els_theta(
    us: np.ndarray, ys: np.ndarray, na: int, nb: int, nc: int, delay: int,
    max_iter: int = 50, tol: float = 1e-10,
) -> np.ndarray:
    """Extended least squares on (already scaled) data; returns θ and sets no state.

    Start from ARX least squares, then repeat LS with the previous iteration's
    prediction errors ε = (A y − q^-d B u)/C as the c-regressors until the relative
    change of θ is below ``tol`` (or ``max_iter`` iterations), C kept stable.
    """
    theta, _ = _els(us, ys, na, nb, nc, delay, max_iter, tol)
    return theta


def _els(us, ys, na, nb, nc, delay, max_iter, tol) -> tuple[np.ndarray, int]:
    phi, t, _ = regression_matrix(us, ys, None, na, nb, 0, delay)
    theta = np.zeros(na + nb + 1 + nc)
    theta[: na + nb + 1] = np.linalg.lstsq(phi, t, rcond=None)[0]
    iters = 0
    if nc:
        for iters in range(1, max_iter + 1):  # noqa: B007 - reported in meta
            e = _pred_errors(theta, us, ys, na, nb, nc, delay)
            phi, t, _ = regression_matrix(us, ys, e, na, nb, nc, delay)
            new = np.linalg.lstsq(phi, t, rcond=None)[0]
            new[na + nb + 1 :] = _stabilise(new[na + nb + 1 :])
            change = np.linalg.norm(new - theta) / max(np.linalg.norm(new), 1e-300)
            theta = new
            if change < tol:
                break
    return theta, iters


def armax_els(
    u: Any,
    y: Any,
    *,
    na: int,
    nb: int,
    nc: int,
    delay: int = 1,
    dt: float = 1.0,
    max_iter: int = 50,
    tol: float = 1e-10,
    refine: bool = True,
) -> ArmaxModel:
    """ARMAX by extended least squares, optionally refined by prediction-error minimisation.

    ELS: start from ARX least squares, then repeat LS with the previous iteration's
    prediction errors ε = (A y − q^-d B u)/C as the c-regressors until the relative
    change of θ is below ``tol`` (or ``max_iter``). With ``refine`` (and nc ≥ 1) the
    result is :func:`~ehss.identification.pem.armax_pem`, which starts from this ELS
    estimate (and from ARX) and minimises Σε² with C kept stable. Data are RMS-scaled
    internally, as in :func:`~ehss.identification.rels`.

    Raises
    ------
    IdentificationError
        If the estimate is not finite.
    """
    u, y, na, nb, nc, delay, dt = _validate(u, y, na, nb, nc, delay, dt)
    max_iter = _order("max_iter", max_iter, 1)
    tol = _real("tol", tol)
    if refine and nc:
        from ehss.identification.pem import armax_pem

        return armax_pem(u, y, na=na, nb=nb, nc=nc, delay=delay, dt=dt)
    su = float(np.sqrt(np.mean(u * u))) or 1.0
    sy = float(np.sqrt(np.mean(y * y))) or 1.0
    us, ys = u / su, y / sy
    n = na + nb + 1 + nc
    theta, iters = _els(us, ys, na, nb, nc, delay, max_iter, tol)
    if not np.all(np.isfinite(theta)):
        raise IdentificationError("extended least squares diverged (non-finite θ)")
    k0 = max(na, nb + delay, nc)
    eps = _pred_errors(theta, us, ys, na, nb, nc, delay)[k0:]
    nv_s = float(eps @ eps / max(eps.size - n, 1))
    # covariance from the linearised regression at the solution: σ² (ΦᵀΦ)⁻¹
    e_full = _pred_errors(theta, us, ys, na, nb, nc, delay)
    phi, _, _ = regression_matrix(us, ys, e_full, na, nb, nc, delay)
    dvec = np.ones(n)
    dvec[na : na + nb + 1] = sy / su
    theta = theta * dvec
    cov = nv_s * np.linalg.pinv(phi.T @ phi) * dvec[:, None] * dvec[None, :]
    meta = {
        "method": "armax_els",
        "n_samples": int(u.size),
        "els_iterations": int(iters),
        "u_scale": su,
        "y_scale": sy,
    }
    nv = nv_s * sy * sy
    return _model(theta, na, nb, nc, delay, dt, nv if math.isfinite(nv) else math.nan, cov,
                  meta)
