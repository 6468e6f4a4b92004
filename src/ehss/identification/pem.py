"""Prediction-error minimisation (PEM) for ARMAX and output-error models.

Both estimators minimise the sum of squared one-step prediction errors
V(θ) = Σ ε(k, θ)² with ``scipy.optimize.least_squares`` (Levenberg–Marquardt, MINPACK),
given the analytic Jacobian, which is the regressor filtered through the predictor's
denominator (Ljung, *System Identification*, 2nd ed., 1999, §10.2):

ARMAX, A y = q^-d B u + C e, θ = [a1..a_na, b0..b_nb, c1..c_nc]:

.. math::

    \\varepsilon(k) = \\frac{A y(k) - B u(k-d)}{C},\\qquad
    \\frac{\\partial\\varepsilon}{\\partial a_i} = \\frac{y(k-i)}{C},\\quad
    \\frac{\\partial\\varepsilon}{\\partial b_j} = -\\frac{u(k-d-j)}{C},\\quad
    \\frac{\\partial\\varepsilon}{\\partial c_i} = -\\frac{\\varepsilon(k-i)}{C}.

Output error, y = q^-d B/F u + e, θ = [f1..f_nf, b0..b_nb]:

.. math::

    \\hat y = \\frac{B}{F} u(k-d),\\quad \\varepsilon = y - \\hat y,\\qquad
    \\frac{\\partial\\varepsilon}{\\partial f_i} = \\frac{\\hat y(k-i)}{F},\\quad
    \\frac{\\partial\\varepsilon}{\\partial b_j} = -\\frac{u(k-d-j)}{F}.

An OE model is returned as an :class:`~ehss.identification.ArmaxModel` with a = c = F:
A y = B u + A e is exactly y = B/F u + e, so one model type serves both.

Safeguards:

* u and y are scaled by their RMS inside (so tolerances mean the same in any units);
  b is de-scaled by s_y/s_u on return;
* the predictor stays stable: a trial point whose C (ARMAX) or F (OE) has a root at or
  beyond ``radius`` (Schur–Cohn test) gets a huge constant residual, so the step is
  rejected and the damping raised (the cost is compared, never differentiated, there);
  every start is stabilised first by reflecting roots into the circle;
* the predictor starts at rest before the first sample (zero initial conditions), and
  the loss counts the samples from max(na, nb + d, nc) on;
* several cheap starts are tried (ARMAX: extended least squares, ARX with C = 1 and,
  when nc ≥ na, the output-error fit with C = F; OE: ARX and Steiglitz–McBride
  iterations) and the lowest loss wins;
* an ARMAX estimate whose A is unstable is flagged (``meta["stable"] = False``) and warned
  about, never returned silently.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import lfilter

from ehss.errors import IdentificationError
from ehss.identification.batch import _stabilise, _validate, els_theta, regression_matrix
from ehss.identification.model import ArmaxModel
from ehss.identification.rels import _order, _real, _rms_scale

__all__ = ["armax_pem", "oe_pem"]

_BARRIER = 1e4  # residual (in RMS units of y) returned for a destabilising trial point


def _radius(p: np.ndarray) -> float:
    """Largest root modulus of the monic polynomial [1, p...] (0 for an empty p)."""
    if p.size == 0:
        return 0.0
    return float(np.max(np.abs(np.roots(np.concatenate([[1.0], p])))))


def _inside(p: np.ndarray, radius: float) -> bool:
    """True if every root of [1, p...] lies strictly inside ``radius`` (Schur–Cohn).

    The roots of z^n + p1 z^(n−1) + … scaled by 1/radius are those of
    [1, p1/r, p2/r², …]; the step-down (Levinson) recursion on that polynomial finds
    its reflection coefficients k, and all |k| < 1 iff all its roots are inside the unit
    circle. O(n²), much cheaper than np.roots inside the optimiser's loop.
    """
    a = np.concatenate([[1.0], p / radius ** np.arange(1, p.size + 1)])
    while a.size > 1:
        k = a[-1] / a[0]
        if not abs(k) < 1.0:
            return False
        a = (a - k * a[::-1])[:-1] / (1.0 - k * k)
    return True


def _solve(fun, jac, x0: np.ndarray, max_nfev: int, tol: float):
    """One Levenberg–Marquardt run; returns (x, cost, nfev)."""
    sol = least_squares(fun, x0, jac=jac, method="lm", x_scale="jac", xtol=tol, ftol=tol,
                        gtol=tol, max_nfev=max_nfev)
    return sol.x, float(sol.cost), int(sol.nfev)


def _covariance(J: np.ndarray, eps: np.ndarray, n_free: int) -> tuple[float, np.ndarray]:
    """σ² (JᵀJ)⁻¹ with σ² = Σε²/(N − p) (the usual PEM covariance, Ljung eq. 9.18)."""
    nv = float(eps @ eps / max(eps.size - n_free, 1))
    return nv, nv * np.linalg.pinv(J.T @ J)


# ------------------------------------------------------------------------------ ARMAX
def _lag(x: np.ndarray, i: int) -> np.ndarray:
    """x(k − i) with zeros before the record (the system at rest before k = 0)."""
    return np.concatenate([np.zeros(i), x[: x.size - i]]) if i else x


def _padded_regressors(us, ys, na, nb, delay) -> np.ndarray:
    """Rows [−y(k−1)..−y(k−na), u(k−d)..u(k−d−nb)] for every k, zero before the record."""
    cols = [-_lag(ys, i) for i in range(1, na + 1)]
    cols += [_lag(us, delay + j) for j in range(nb + 1)]
    return np.column_stack(cols)


def _armax_errors(theta, phi, ys, na, nb, radius):
    """ε = (A y − q^-d B u)/C for every k, zero initial conditions; None if C unstable."""
    c = theta[na + nb + 1 :]
    if not _inside(c, radius):
        return None
    return lfilter([1.0], np.concatenate([[1.0], c]), ys - phi @ theta[: na + nb + 1])


def _armax_residual(theta, phi, ys, na, nb, nc, k0, radius):
    eps = _armax_errors(theta, phi, ys, na, nb, radius)
    return np.full(ys.size - k0, _BARRIER) if eps is None else eps[k0:]


def _armax_jacobian(theta, phi, ys, na, nb, nc, k0, radius):
    cpoly = np.concatenate([[1.0], theta[na + nb + 1 :]])
    eps = _armax_errors(theta, phi, ys, na, nb, radius)
    # ∂ε/∂θ_ab = −φ/C (φ holds −y(k−i) and u(k−d−j)); ∂ε/∂c_i = −ε(k−i)/C
    cols = [-phi] + [-_lag(eps, i)[:, None] for i in range(1, nc + 1)]
    return lfilter([1.0], cpoly, np.hstack(cols), axis=0)[k0:]


def armax_pem(
    u: Any,
    y: Any,
    *,
    na: int,
    nb: int,
    nc: int,
    delay: int = 1,
    dt: float = 1.0,
    radius: float = 0.999,
    max_nfev: int = 200,
    tol: float = 1e-10,
) -> ArmaxModel:
    """ARMAX model A y = q^-d B u + C e by prediction-error minimisation.

    Parameters
    ----------
    u, y : array_like, shape (n_samples,)
        Input and output (deviations from the operating point).
    na, nb, nc : int
        Orders of A (≥ 1), B (nb + 1 coefficients) and C (≥ 0; nc = 0 gives ARX).
    delay : int
        Input delay d in samples.
    dt : float
        Sample period (s).
    radius : float
        Roots of C are kept inside this radius (0 < radius < 1).
    max_nfev : int
        Evaluation budget of each start's Levenberg–Marquardt run.
    tol : float
        ``xtol``, ``ftol`` and ``gtol`` of ``least_squares``.

    Returns
    -------
    ArmaxModel
        ``covariance`` is σ² (JᵀJ)⁻¹ at the optimum; ``meta`` holds method
        ("armax_pem"), n_samples, start (which start won), starts (their losses), nfev,
        stable, u_scale, y_scale.

    Warns
    -----
    EhssWarning
        If A is unstable (also ``meta["stable"] = False``).

    Examples
    --------
    >>> import numpy as np
    >>> from scipy.signal import lfilter
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal(3000)
    >>> e = 0.1 * rng.standard_normal(3000)
    >>> y = lfilter([0, 0.5], [1, -0.8], u) + lfilter([1, 0.5], [1, -0.8], e)
    >>> m = armax_pem(u, y, na=1, nb=0, nc=1)
    >>> bool(abs(m.a[1] + 0.8) < 0.01 and abs(m.c[1] - 0.5) < 0.05)
    True
    """
    u, y, na, nb, nc, delay, dt = _validate(u, y, na, nb, nc, delay, dt)
    radius = _radius_setting(radius)
    max_nfev = _order("max_nfev", max_nfev, 1)
    tol = _real("tol", tol)
    su, sy = _rms_scale(u), _rms_scale(y)
    us, ys = u / su, y / sy
    phi, t, k0 = regression_matrix(us, ys, None, na, nb, 0, delay)
    k0 = max(k0, nc)
    n_ab = na + nb + 1
    starts: dict[str, np.ndarray] = {}
    arx = np.zeros(n_ab + nc)
    arx[:n_ab] = np.linalg.lstsq(phi, t, rcond=None)[0]
    if nc:
        els = els_theta(us, ys, na, nb, nc, delay)
        els[n_ab:] = _stabilise(els[n_ab:], 0.95 * radius)
        starts["els"] = els
    starts["arx"] = arx
    if nc >= na:  # output-error start: C = F (white noise at the output)
        oe = _oe_fit(us, ys, na, nb, delay, radius, max_nfev, tol)[0]
        starts["oe"] = np.concatenate([oe, oe[:na], np.zeros(nc - na)])
    args = (_padded_regressors(us, ys, na, nb, delay), ys, na, nb, nc, k0, radius)
    best = None
    losses = {}
    nfev_total = 0
    for name, x0 in starts.items():
        if nc:
            x, cost, nfev = _solve(lambda th: _armax_residual(th, *args),
                                   lambda th: _armax_jacobian(th, *args), x0, max_nfev, tol)
        else:  # ARX: the loss is quadratic, least squares is the optimum
            x, cost, nfev = x0, 0.5 * float(np.sum(_armax_residual(x0, *args) ** 2)), 0
        nfev_total += nfev
        losses[name] = 2.0 * cost / (ys.size - k0)
        if not np.all(np.isfinite(x)):
            continue
        # a stable A beats any unstable one: a lower loss bought with a pole outside the
        # unit circle is over-fitting (a near pole-zero-noise cancellation), not a model
        key = (_radius(x[:na]) >= 1.0, cost)
        if best is None or key < best[1]:
            best = (name, key, x)
    if best is None:
        raise IdentificationError("prediction-error minimisation diverged (non-finite θ)")
    name, _, theta = best
    eps = _armax_residual(theta, *args)
    J = _armax_jacobian(theta, *args)
    nv_s, cov_s = _covariance(J, eps, theta.size)
    dvec = np.ones(theta.size)
    dvec[na:n_ab] = sy / su
    meta = {
        "method": "armax_pem",
        "n_samples": int(u.size),
        "start": name,
        "starts": losses,
        "nfev": nfev_total,
        "c_radius": radius,
        "u_scale": su,
        "y_scale": sy,
    }
    return _finish(theta * dvec, cov_s * np.outer(dvec, dvec), nv_s * sy * sy, na, nb, nc,
                   delay, dt, meta, k0)


# ------------------------------------------------------------------------------ OE
def _oe_simulate(theta, us, nf, nb, delay):
    f = np.concatenate([[1.0], theta[:nf]])
    bd = np.concatenate([np.zeros(delay), theta[nf:]])
    return lfilter(bd, f, us), f


def _oe_residual(theta, us, ys, nf, nb, delay, k0, radius):
    if not _inside(theta[:nf], radius):
        return np.full(ys.size - k0, _BARRIER)
    yhat, _ = _oe_simulate(theta, us, nf, nb, delay)
    return (ys - yhat)[k0:]


def _oe_jacobian(theta, us, ys, nf, nb, delay, k0, radius):
    yhat, f = _oe_simulate(theta, us, nf, nb, delay)
    N = us.size
    # ∂ε/∂f_i = ŷ(k−i)/F ; ∂ε/∂b_j = −u(k−d−j)/F
    cols = [np.concatenate([np.zeros(i), yhat[: N - i]]) for i in range(1, nf + 1)]
    cols += [-np.concatenate([np.zeros(delay + j), us[: N - delay - j]])
             for j in range(nb + 1)]
    return lfilter([1.0], f, np.column_stack(cols), axis=0)[k0:]


def _steiglitz_mcbride(us, ys, nf, nb, delay, theta, radius, iterations=8):
    """Refilter u, y by 1/F and refit ARX (Steiglitz & McBride 1965): an OE start."""
    for _ in range(iterations):
        f = np.concatenate([[1.0], theta[:nf]])
        uf, yf = lfilter([1.0], f, us), lfilter([1.0], f, ys)
        phi, t, _ = regression_matrix(uf, yf, None, nf, nb, 0, delay)
        new = np.linalg.lstsq(phi, t, rcond=None)[0]
        new[:nf] = _stabilise(new[:nf], 0.95 * radius)
        if not np.all(np.isfinite(new)):
            break
        theta = new
    return theta


def _oe_fit(us, ys, nf, nb, delay, radius, max_nfev, tol):
    """OE PEM on scaled data from the ARX and Steiglitz–McBride starts; best wins."""
    phi, t, k0 = regression_matrix(us, ys, None, nf, nb, 0, delay)
    arx = np.linalg.lstsq(phi, t, rcond=None)[0]
    arx[:nf] = _stabilise(arx[:nf], 0.95 * radius)
    starts = {"arx": arx, "steiglitz_mcbride": _steiglitz_mcbride(us, ys, nf, nb, delay,
                                                                   arx.copy(), radius)}
    args = (us, ys, nf, nb, delay, k0, radius)
    best = None
    losses = {}
    nfev_total = 0
    for name, x0 in starts.items():
        x, cost, nfev = _solve(lambda th: _oe_residual(th, *args),
                               lambda th: _oe_jacobian(th, *args), x0, max_nfev, tol)
        nfev_total += nfev
        losses[name] = 2.0 * cost / (ys.size - k0)
        if np.all(np.isfinite(x)) and (best is None or cost < best[1]):
            best = (name, cost, x)
    if best is None:
        raise IdentificationError("output-error minimisation diverged (non-finite θ)")
    return best[2], best[0], losses, nfev_total, k0


def oe_pem(
    u: Any,
    y: Any,
    *,
    nf: int,
    nb: int,
    delay: int = 1,
    dt: float = 1.0,
    radius: float = 0.9999,
    max_nfev: int = 200,
    tol: float = 1e-10,
) -> ArmaxModel:
    """Output-error model y = q^-d B/F u + e by prediction-error minimisation.

    Parameters
    ----------
    u, y : array_like, shape (n_samples,)
        Input and output (deviations from the operating point).
    nf, nb : int
        Orders of F (≥ 1) and B (nb + 1 coefficients).
    delay : int
        Input delay d in samples.
    dt : float
        Sample period (s).
    radius : float
        Roots of F (the model's poles) are kept inside this radius (0 < radius < 1), so
        the model is always stable.
    max_nfev, tol
        As in :func:`armax_pem`.

    Returns
    -------
    ArmaxModel
        With a = c = F (na = nc = nf): A y = B u + A e is y = B/F u + e. ``covariance`` is
        σ² (JᵀJ)⁻¹ mapped onto θ = [f, b, f]; ``meta["method"]`` is "oe_pem".

    Examples
    --------
    >>> import numpy as np
    >>> from scipy.signal import lfilter
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal(3000)
    >>> y = lfilter([0, 0.5], [1, -0.8], u) + 0.1 * rng.standard_normal(3000)
    >>> m = oe_pem(u, y, nf=1, nb=0)
    >>> bool(abs(m.a[1] + 0.8) < 0.01) and bool(np.array_equal(m.a, m.c))
    True
    """
    u, y, nf, nb, _, delay, dt = _validate(u, y, nf, nb, 0, delay, dt)
    radius = _radius_setting(radius)
    max_nfev = _order("max_nfev", max_nfev, 1)
    tol = _real("tol", tol)
    su, sy = _rms_scale(u), _rms_scale(y)
    us, ys = u / su, y / sy
    theta, name, losses, nfev_total, k0 = _oe_fit(us, ys, nf, nb, delay, radius, max_nfev, tol)
    args = (us, ys, nf, nb, delay, k0, radius)
    eps = _oe_residual(theta, *args)
    J = _oe_jacobian(theta, *args)
    nv_s, cov_s = _covariance(J, eps, theta.size)
    dvec = np.ones(theta.size)
    dvec[nf:] = sy / su
    theta = theta * dvec
    cov_s = cov_s * np.outer(dvec, dvec)
    # θ of the ARMAX form is [f, b, f]: M maps [f, b] onto it, cov = M cov Mᵀ
    M = np.vstack([np.eye(theta.size), np.eye(nf, theta.size)])
    full = np.concatenate([theta, theta[:nf]])
    meta = {
        "method": "oe_pem",
        "n_samples": int(u.size),
        "start": name,
        "starts": losses,
        "nfev": nfev_total,
        "f_radius": radius,
        "u_scale": su,
        "y_scale": sy,
    }
    return _finish(full, M @ cov_s @ M.T, nv_s * sy * sy, nf, nb, nf, delay, dt, meta, k0)


# ------------------------------------------------------------------------------ shared
def _radius_setting(radius: Any) -> float:
    from ehss.errors import ParameterError

    r = _real("radius", radius)
    if not 0.0 < r < 1.0:
        raise ParameterError(f"radius={radius!r} must be in (0, 1)")
    return r


def _finish(theta, cov, nv, na, nb, nc, delay, dt, meta, k0) -> ArmaxModel:
    if not np.all(np.isfinite(theta)):
        raise IdentificationError("the estimate does not fit float64 in physical units")
    a = np.concatenate([[1.0], theta[:na]])
    radius = _radius(a[1:])
    model = ArmaxModel(
        a=a, b=theta[na : na + nb + 1], c=np.concatenate([[1.0], theta[na + nb + 1 :]]),
        delay=delay, dt=dt, noise_variance=nv if math.isfinite(nv) else math.nan,
        covariance=cov if np.all(np.isfinite(cov)) else None,
        meta={**meta, "first_sample": int(k0), "stable": radius < 1.0,
              "max_pole_radius": radius},
    )
    if radius >= 1.0:
        model.check(warn=True)  # EhssWarning: an unstable model is never silent
    return model
