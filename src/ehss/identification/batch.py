"""Batch references for RELS: ARX least squares and ARMAX extended least squares.

These are the slow-but-sure estimators RELS is checked against (with λ = 1 and a large
P(0), RELS approaches :func:`arx_ls` on ARX data); the extended least squares estimate is
also the first start of the prediction-error fit (:func:`~ehss.identification.pem.
armax_pem`), the default ARMAX estimator.
"""

from __future__ import annotations

from typing import Any, Unpack

import numpy as np
from scipy.linalg import solve_triangular

from ehss.errors import IdentificationError
from ehss.identification import _pem_kernels as _pk
from ehss.identification._common import (
    ArmaxOrders,
    OrderKeywords,
    check_batch,
    first_sample,
    prediction_errors,
    regression_matrix,
    rms_scale,
    solver_budget,
    stabilise,
    theta_scale,
)
from ehss.identification.model import ArmaxModel

__all__ = ["arx_ls", "armax_els", "els_theta", "regression_matrix"]


def arx_ls(u: Any, y: Any, *, na: int, nb: int, delay: int = 1, dt: float = 1.0) -> ArmaxModel:
    """ARX model A y = q^-d B u + ξ by linear least squares (``numpy.linalg.lstsq``).

    The first max(na, nb + d) samples only feed regressors. ``covariance`` is
    σ² (ΦᵀΦ)⁻¹ with σ² the residual variance (dof-corrected).
    """
    o = ArmaxOrders(na=na, nb=nb, nc=0, delay=delay, dt=dt)
    u, y = check_batch(u, y, o)
    na, nb, delay, dt = o.na, o.nb, o.delay, o.dt
    phi, t, _ = regression_matrix(u, y, None, na, nb, 0, delay)
    theta, *_ = np.linalg.lstsq(phi, t, rcond=None)
    res = t - phi @ theta
    dof = max(t.size - theta.size, 1)
    nv = float(res @ res / dof)
    cov = nv * np.linalg.pinv(phi.T @ phi)
    meta = {"method": "arx_ls", "n_samples": int(u.size)}
    return ArmaxModel.from_theta(theta, na=na, nb=nb, nc=0, delay=delay, dt=dt,
                                 noise_variance=nv, covariance=cov, meta=meta)


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


def _els(us: np.ndarray, ys: np.ndarray, na: int, nb: int, nc: int, delay: int,
         max_iter: int, tol: float) -> tuple[np.ndarray, int]:
    theta = np.zeros(na + nb + 1 + nc)
    theta[: na + nb + 1] = gram_lstsq(np.vstack([ys, us]), _pk.els_layout(na, nb, 0, delay),
                                      first_sample(na, nb, 0, delay))
    iters = 0
    if nc:
        layout, k0 = _pk.els_layout(na, nb, nc, delay), first_sample(na, nb, nc, delay)
        signals = np.vstack([ys, us, ys])  # y, u and the c-regressors e, set below
        for iters in range(1, max_iter + 1):  # noqa: B007 - reported in meta
            signals[2] = _pk.armax_errors(theta, us, ys, na, nb, nc, delay)
            new = gram_lstsq(signals, layout, k0)
            new[na + nb + 1 :] = _stable_c(new[na + nb + 1 :])
            change = np.linalg.norm(new - theta) / max(float(np.linalg.norm(new)), 1e-300)
            theta = new
            if change < tol:
                break
    return theta, iters


def _stable_c(c: np.ndarray, radius: float = 0.99) -> np.ndarray:
    """c, or :func:`stabilise`'s reflection of it when a root of [1, c...] is at or
    beyond ``radius`` (Schur–Cohn test first: no polynomial roots when all are inside)."""
    return c if _pk.roots_inside(c, radius) else stabilise(c, radius)


#: largest condition number of Φ (columns scaled to unit norm) whose least-squares
#: problem is solved through ΦᵀΦ: its relative error grows as ε κ² there (ε = 2.2e-16),
#: as ε κ (plus ε κ² times the relative residual) through ``lstsq``; up to κ = 1e5 that
#: is ≤ 2e-6, the tolerance to which an extended-least-squares start is wanted (it is a
#: start: the prediction-error fit takes it from there). Beyond it, ``lstsq`` of Φ.
_COND_GRAM = 1e5


def gram_lstsq(signals: np.ndarray, layout: tuple[np.ndarray, np.ndarray, np.ndarray],
               k0: int) -> np.ndarray:
    """θ minimising ‖t − Φθ‖ where the columns of [−Φ t] are delayed rows of ``signals``
    (``layout``: their (row, lag, sign), as :func:`._pem_kernels.els_layout` gives them),
    rows k ≥ k0.

    Through the Gram matrix G = [−Φ t]ᵀ[−Φ t] (compiled, Φ not formed) and its Cholesky
    factor when Φ is well enough conditioned (``_COND_GRAM``): with RᵀR = ΦᵀΦ and
    Rᵀq = −Φᵀt (:func:`._pem_kernels.reduce_gram`), ‖t − Φθ‖² = ‖q + Rθ‖² + ρ², so
    θ = −R⁻¹q. Otherwise Φ is formed and solved by ``numpy.linalg.lstsq`` (SVD).
    """
    row, lag, sign = layout
    r, Rz = _pk.reduce_gram(_pk.gram(signals, row, lag, sign, k0), _COND_GRAM)
    n = row.size - 1
    if r.size == 0:
        A = _pk.columns(signals, row, lag, sign, k0)
        return np.linalg.lstsq(A[:, :n], -A[:, n], rcond=None)[0]
    return -solve_triangular(Rz[:n], r[:n])


def armax_els(
    u: Any, y: Any, *, max_iter: int = 50, tol: float = 1e-10, **orders: Unpack[OrderKeywords],
) -> ArmaxModel:
    """ARMAX model A y = q^-d B u + C e by extended least squares (ELS).

    Start from ARX least squares, then repeat LS with the previous iteration's
    prediction errors ε = (A y − q^-d B u)/C as the c-regressors (the batch form of the
    paper's eq. 19) until the relative change of θ is below ``tol`` (or ``max_iter``
    iterations), C kept inside radius 0.99. Data are RMS-scaled internally, as in
    :func:`~ehss.identification.rels`. ELS is not the prediction-error optimum (its fixed
    point is biased where 1/C − 1/2 is not positive real); :func:`~ehss.identification.
    pem.armax_pem` starts from it and minimises Σε².

    Parameters
    ----------
    u, y : array_like, shape (n_samples,)
        Input and output (deviations from the operating point).
    max_iter : int
        Most least-squares iterations (≥ 1).
    tol : float
        Relative change of θ (≥ 0) below which the iterations stop.
    na, nb, nc, delay, dt
        Orders, input delay in samples (default 1) and sample period in s (default 1).

    Returns
    -------
    ArmaxModel
        ``covariance`` is σ² (ΦᵀΦ)⁻¹ of the linearised regression at the solution;
        ``meta`` holds method ("armax_els"), n_samples, els_iterations, u_scale, y_scale.

    Raises
    ------
    IdentificationError
        If the estimate is not finite.

    Examples
    --------
    >>> import numpy as np
    >>> true = ArmaxModel(a=[1, -0.8], b=[0.5], c=[1, 0.5])
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal(5000)
    >>> y = true.simulate(u, innovation=0.1 * rng.standard_normal(5000))
    >>> m = armax_els(u, y, na=1, nb=0, nc=1)
    >>> m.meta["method"], bool(abs(m.a[1] + 0.8) < 0.01)
    ('armax_els', True)
    """
    o = ArmaxOrders(**orders)
    u, y = check_batch(u, y, o)
    max_iter, tol = solver_budget(max_iter, "max_iter", tol)
    na, nb, nc, delay, dt = o.na, o.nb, o.nc, o.delay, o.dt
    su, sy = rms_scale(u), rms_scale(y)
    us, ys = u / su, y / sy
    n = na + nb + 1 + nc
    theta, iters = _els(us, ys, na, nb, nc, delay, max_iter, tol)
    if not np.all(np.isfinite(theta)):
        raise IdentificationError("extended least squares diverged (non-finite θ)")
    e_full = prediction_errors(theta, us, ys, na, nb, nc, delay)
    eps = e_full[o.first_sample:]
    nv_s = float(eps @ eps / max(eps.size - n, 1))
    # covariance from the linearised regression at the solution: σ² (ΦᵀΦ)⁻¹
    phi, _, _ = regression_matrix(us, ys, e_full, na, nb, nc, delay)
    dvec = theta_scale(na, nb, nc, su, sy)
    cov = nv_s * np.linalg.pinv(phi.T @ phi) * dvec[:, None] * dvec[None, :]
    meta = {
        "method": "armax_els",
        "n_samples": int(u.size),
        "els_iterations": int(iters),
        "u_scale": su,
        "y_scale": sy,
    }
    return ArmaxModel.from_theta(theta * dvec, na=na, nb=nb, nc=nc, delay=delay, dt=dt,
                                 noise_variance=nv_s * sy * sy, covariance=cov, meta=meta)
