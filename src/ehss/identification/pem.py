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

The prediction errors and the Jacobians are compiled
(:mod:`ehss.identification._pem_kernels`, GIL released): since filtering commutes with a
delay, each Jacobian filters y, u and ε (ARMAX) or ŷ and u (OE) once and takes its
columns as delayed copies; the errors of the last trial point are reused for its
Jacobian. Levenberg–Marquardt is handed the same least-squares problem reduced to
n + 1 rows (R and Qᵀε of J's QR, formed from JᵀJ and Jᵀε where J is well enough
conditioned): the same steps and tests at a fraction of the cost (``_Predictor``).

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
  iterations), and for ARMAX any start the caller gives (``theta0``: the order search
  passes a smaller neighbour's estimate, padded with zeros), and the lowest loss wins;
* an ARMAX estimate whose A is unstable is flagged (``meta["stable"] = False``) and warned
  about, never returned silently.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, Unpack

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import lfilter

from ehss._checks import check_int
from ehss.errors import DataError, IdentificationError, ParameterError
from ehss.identification import _pem_kernels as _pk
from ehss.identification._common import (
    ArmaxOrders,
    OrderKeywords,
    check_batch,
    check_theta0,
    first_sample,
    regression_matrix,
    rms_scale,
    root_radius,
    solver_budget,
    stabilise,
    start_radius,
    theta_scale,
)
from ehss.identification.batch import els_theta
from ehss.identification.model import ArmaxModel

__all__ = ["armax_pem", "oe_pem"]

#: The starts of :func:`oe_pem` without a given one: the ARX fit, and the
#: Steiglitz–McBride iterations from it
OE_STARTS = ("arx", "steiglitz_mcbride")

_BARRIER = 1e4  # residual (in RMS units of y) returned for a destabilising trial point


def _radius(p: np.ndarray) -> float:
    """Largest root modulus of the monic polynomial [1, p...] (0 for an empty p)."""
    if p.size == 0:
        return 0.0
    return float(np.max(np.abs(np.roots(np.concatenate([[1.0], p])))))


def _inside(p: np.ndarray, radius: float) -> bool:
    """True if every root of [1, p...] lies strictly inside ``radius`` (Schur–Cohn)."""
    return bool(_pk.roots_inside(np.ascontiguousarray(p, dtype=np.float64), float(radius)))


def _solve(fun: Callable[[np.ndarray], np.ndarray], jac: Callable[[np.ndarray], np.ndarray],
           x0: np.ndarray, max_nfev: int, tol: float) -> tuple[np.ndarray, float, int]:
    """One Levenberg–Marquardt run; returns (x, cost, nfev)."""
    sol = least_squares(fun, x0, jac=jac, method="lm", x_scale="jac", xtol=tol, ftol=tol,
                        gtol=tol, max_nfev=max_nfev)
    return sol.x, float(sol.cost), int(sol.nfev)


def _covariance(J: np.ndarray, eps: np.ndarray, n_free: int) -> tuple[float, np.ndarray]:
    """σ² (JᵀJ)⁻¹ with σ² = Σε²/(N − p) (the usual PEM covariance, Ljung eq. 9.18)."""
    nv = float(eps @ eps / max(eps.size - n_free, 1))
    return nv, nv * np.linalg.pinv(J.T @ J)


#: largest condition number of J (columns scaled to unit norm) whose reduced problem
#: is formed from JᵀJ: through JᵀJ the relative error of R grows as ε κ² (ε = 2.2e-16),
#: through a QR of J as ε κ. Up to κ = 1e5 (ε κ² ≤ 2e-6) the steps agree with MINPACK's
#: own to about six digits, which leaves its iterates as they are: on the report's
#: position record (κ up to 3e4 over the 32 candidates of ``ehss order``) every run
#: takes the same number of evaluations and ends at the same cost to 1e-11. Oversampled
#: records of high order reach κ = 1e8–1e9 and are factored by QR.
_COND_GRAM = 1e5


class _Reduced:
    """Levenberg–Marquardt on a least-squares problem given as its reduction to n + 1
    rows (``_reduce``), with a barrier where θ is not ``feasible``."""

    def _reduce(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
        raise NotImplementedError

    def feasible(self, theta: np.ndarray) -> bool:
        raise NotImplementedError

    def n_rows(self) -> int:
        raise NotImplementedError

    def _reduced_residual(self, theta: np.ndarray) -> np.ndarray:
        if not self.feasible(theta):
            out = np.zeros(theta.size + 1)
            out[-1] = _BARRIER * np.sqrt(self.n_rows())
            return out
        return self._reduce(theta)[0]

    def _reduced_jacobian(self, theta: np.ndarray) -> np.ndarray:
        return self._reduce(theta)[1]

    def fit(self, x0: np.ndarray, max_nfev: int, tol: float) -> tuple[np.ndarray, float, int]:
        """Levenberg–Marquardt from ``x0`` on the reduced problem: (θ, cost, nfev).

        From a start whose Jacobian is too ill-conditioned for JᵀJ (``_COND_GRAM``),
        MINPACK is given one more parameter that changes nothing (a zero last column).
        scipy's C MINPACK (1.15 to 1.17) reads one element past the Jacobian when it
        recomputes the norm of its last column (``qrfac``: ``enorm(m - j, ...)`` where
        MINPACK has ``m - j - 1``), which it does when that column's remaining norm falls
        below 7·10⁻⁸ of its last one, on such Jacobians: the fit then depends on memory
        it does not own and differs from one process to the next. A zero column's norm
        is never recomputed, and pivoting keeps it last. (A start below ``_COND_GRAM``
        whose iterates reach κ ≈ 10⁷ is not covered.)"""
        if not self._ill_conditioned(x0):
            return _solve(self._reduced_residual, self._reduced_jacobian, x0, max_nfev, tol)
        n = x0.size

        def jac(x: np.ndarray) -> np.ndarray:
            J = self._reduced_jacobian(x[:n])
            return np.column_stack([J, np.zeros(J.shape[0])])

        x, cost, nfev = _solve(lambda x: self._reduced_residual(x[:n]), jac,
                               np.append(x0, 0.0), max_nfev, tol)
        return x[:n], cost, nfev

    def _ill_conditioned(self, x0: np.ndarray) -> bool:
        """Whether the reduction at ``x0`` is a QR of [J ε] (J, its columns scaled to
        unit norm, has a condition number above ``_COND_GRAM``)."""
        return self.feasible(x0) and self._reduce(x0)[2]


class _Predictor(_Reduced):
    """Residuals ε(k ≥ k0) and Jacobian of one model structure on one scaled record.

    The columns of the Jacobian J and the residual ε are delayed copies of a few
    filtered signals (:mod:`._pem_kernels`); they are formed for the covariance only.
    Levenberg–Marquardt is given the same problem reduced to n + 1 rows instead: with
    [J ε] = Q [R q; 0 ρ] (R upper triangular, n × n), ‖ε + J p‖² = ‖q + R p‖² + ρ² for
    every step p, so the residual [q; ρ] and the Jacobian [R; 0] give MINPACK the same
    costs, steps, column norms and convergence tests as ε and J, while its QR works on
    (n + 1) × n instead of N × n. R is the Cholesky factor of JᵀJ, q = R⁻ᵀ Jᵀε, and
    ρ² = εᵀε − qᵀq (εᵀε summed directly, so that the cost is that of ε itself); JᵀJ and
    Jᵀε are dot products of the delayed signals, in the compiled :func:`gram`, and J
    is not formed. When J is too ill-conditioned for that (``_COND_GRAM``), R, q and ρ
    come from a QR of [J ε] instead.

    A θ whose predictor polynomial (C for ARMAX, F for OE) has a root at or beyond
    ``radius`` gets a residual of the norm of N − k0 entries ``_BARRIER`` (the step is
    rejected, the damping raised). The last θ and its filtered signals are kept:
    ``least_squares`` asks for the Jacobian at the point whose residuals it has just had.
    """

    def __init__(self, us: np.ndarray, ys: np.ndarray, na: int, nb: int, nc: int,
                 delay: int, k0: int, radius: float, *, oe: bool = False) -> None:
        self.us, self.ys = us, ys
        self.na, self.nb, self.nc, self.delay, self.k0 = na, nb, nc, delay, k0
        self.radius, self.oe = radius, oe
        layout = _pk.oe_layout(na, nb, delay) if oe else _pk.armax_layout(na, nb, nc, delay)
        self.layout: tuple[np.ndarray, np.ndarray, np.ndarray] = layout
        self._theta: np.ndarray | None = None
        self._signals = np.empty((0, 0))
        self._reduced: tuple[np.ndarray, np.ndarray, bool] | None = None

    def _guard(self, theta: np.ndarray) -> np.ndarray:
        return theta[: self.na] if self.oe else theta[self.na + self.nb + 1 :]

    def _signals_at(self, theta: np.ndarray) -> np.ndarray:
        """The filtered signals at θ (rows of :func:`armax_filtered`/:func:`oe_signals`,
        the residual last), from the cache if there."""
        if self._theta is None or not np.array_equal(theta, self._theta):
            th = np.ascontiguousarray(theta, dtype=np.float64)
            if self.oe:
                yhat = _pk.oe_simulate(th, self.us, self.na, self.nb, self.delay)
                sig = _pk.oe_signals(th, self.us, yhat, self.ys - yhat, self.na)
            else:
                sig = _pk.armax_filtered(th, self.us, self.ys, self.na, self.nb, self.nc,
                                         self.delay)
            self._theta, self._signals, self._reduced = th.copy(), sig, None
        return self._signals

    def residual(self, theta: np.ndarray) -> np.ndarray:
        if not _inside(self._guard(theta), self.radius):
            return np.full(self.ys.size - self.k0, _BARRIER)
        return self._signals_at(theta)[-1, self.k0 :]

    def jacobian(self, theta: np.ndarray) -> np.ndarray:
        row, lag, sign = self.layout
        n = row.size - 1
        return _pk.columns(self._signals_at(theta), row[:n], lag[:n], sign[:n], self.k0)

    def gram(self, theta: np.ndarray) -> np.ndarray:
        """[J ε]ᵀ[J ε] at θ (:func:`._pem_kernels.gram`)."""
        row, lag, sign = self.layout
        return _pk.gram(self._signals_at(theta), row, lag, sign, self.k0)

    def stacked(self, theta: np.ndarray) -> np.ndarray:
        """[J ε] at θ."""
        return np.column_stack([self.jacobian(theta), self.residual(theta)])

    def _reduce(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
        """([q; ρ], [R; 0]) at θ (:func:`_reduced`)."""
        self._signals_at(theta)
        if self._reduced is None:
            self._reduced = _reduced(self.gram(theta), lambda: self.stacked(theta))
        return self._reduced

    def feasible(self, theta: np.ndarray) -> bool:
        return _inside(self._guard(theta), self.radius)

    def n_rows(self) -> int:
        return self.ys.size - self.k0


class _Joint(_Reduced):
    """Records of one model fitted together, each record's errors times its weight.

    Each record runs from rest at its own start (:class:`_Predictor`); the joint
    problem's [J ε]ᵀ[J ε] is the sum of theirs times the squared weights, reduced as
    one record's is (:func:`_reduced`). A record that on its own determines only some
    directions of θ (a band-limited drive) is then well conditioned with a record
    that determines the others.
    """

    def __init__(self, problems: list[_Predictor], weights: list[float]) -> None:
        self.problems, self.weights = problems, weights
        self._theta: np.ndarray | None = None
        self._reduced: tuple[np.ndarray, np.ndarray, bool] | None = None

    def residual(self, theta: np.ndarray) -> np.ndarray:
        return np.concatenate([w * p.residual(theta)
                               for p, w in zip(self.problems, self.weights, strict=True)])

    def jacobian(self, theta: np.ndarray) -> np.ndarray:
        return np.vstack([w * p.jacobian(theta)
                          for p, w in zip(self.problems, self.weights, strict=True)])

    def _reduce(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
        if self._theta is None or not np.array_equal(theta, self._theta):
            pairs = list(zip(self.problems, self.weights, strict=True))
            G = np.sum([w * w * p.gram(theta) for p, w in pairs], axis=0)
            self._reduced = _reduced(G, lambda: np.vstack([w * p.stacked(theta)
                                                           for p, w in pairs]))
            self._theta = np.array(theta, dtype=float)
        assert self._reduced is not None
        return self._reduced

    def feasible(self, theta: np.ndarray) -> bool:
        return self.problems[0].feasible(theta)

    def n_rows(self) -> int:
        return sum(p.n_rows() for p in self.problems)


def _reduced(G: np.ndarray, stacked: Callable[[], np.ndarray]
             ) -> tuple[np.ndarray, np.ndarray, bool]:
    """([q; ρ], [R; 0], by QR) of a least-squares problem from its G = [J ε]ᵀ[J ε]
    (:func:`._pem_kernels.reduce_gram`), or from a QR of [J ε] (``stacked()``) when J is
    too ill-conditioned for JᵀJ (then ``by QR`` is True)."""
    r, Jr = _pk.reduce_gram(G, _COND_GRAM)
    if r.size:
        return r, Jr, False
    n = G.shape[0] - 1
    # a trial θ whose errors grow without bound over the rows overflows [J ε]: the
    # reduction is then not finite, which the fits check in what they return (θ,
    # the covariance) as they check every other way to diverge; numpy's warning of
    # the overflow on its way there is no news to the user
    with np.errstate(over="ignore", invalid="ignore"):
        Rq: np.ndarray = np.linalg.qr(stacked(), mode="r")  # type: ignore[assignment]
    return (np.append(Rq[:n, n], abs(Rq[n, n])),
            np.vstack([Rq[:n, :n], np.zeros((1, n))]), True)


# ------------------------------------------------------------------------------ ARMAX
def armax_pem(
    u: Any,
    y: Any,
    *,
    radius: float = 0.999,
    max_nfev: int = 200,
    tol: float = 1e-10,
    theta0: Any = None,
    smaller_c: bool = False,
    **orders: Unpack[OrderKeywords],
) -> ArmaxModel:
    """ARMAX model A y = q^-d B u + C e by prediction-error minimisation.

    Parameters
    ----------
    u, y : array_like, shape (n_samples,)
        Input and output (deviations from the operating point).
    radius : float
        Roots of C are kept inside this radius (0 < radius < 1).
    max_nfev : int
        Evaluation budget of each start's Levenberg–Marquardt run.
    tol : float
        ``xtol``, ``ftol`` and ``gtol`` of ``least_squares``.
    theta0 : array_like, shape (na + nb + 1 + nc,), optional
        One more start, in physical units: e.g. the estimate of a neighbouring smaller
        structure padded with zeros (what the order search passes), so that the fit
        cannot end worse than that. Tried after the cheap starts, which win ties;
        ignored for nc = 0, where least squares is the optimum.
    smaller_c : bool
        With nc ≥ 2 and no ``theta0``: start also from the fit of the same structure with
        one order less of C (itself fitted so), padded with a zero — the neighbour
        start of the order search, which passes that fit as ``theta0`` instead of
        fitting it again, so that a refit of a pick gives the same model. (For nc = 1
        the neighbour, C = 1, is the ARX start.)
    na, nb, nc : int
        Orders of A (≥ 1), B (nb + 1 coefficients) and C (≥ 0; nc = 0 gives ARX).
    delay : int
        Input delay d in samples (default 1).
    dt : float
        Sample period (s, default 1).

    Returns
    -------
    ArmaxModel
        ``covariance`` is σ² (JᵀJ)⁻¹ at the optimum; ``meta`` holds method
        ("armax_pem"), n_samples, start (which start won: "els", "arx", "oe" or
        "theta0"), starts (their losses), nfev, stable, u_scale, y_scale.

    Warns
    -----
    EhssWarning
        If A is unstable (also ``meta["stable"] = False``).

    Examples
    --------
    >>> import numpy as np
    >>> true = ArmaxModel(a=[1, -0.8], b=[0.5], c=[1, 0.5])
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal(3000)
    >>> y = true.simulate(u, innovation=0.1 * rng.standard_normal(3000))
    >>> m = armax_pem(u, y, na=1, nb=0, nc=1)
    >>> bool(abs(m.a[1] + 0.8) < 0.01 and abs(m.c[1] - 0.5) < 0.05)
    True
    """
    o = ArmaxOrders(**orders)
    u, y = check_batch(u, y, o)
    radius = root_radius(radius)
    max_nfev, tol = solver_budget(max_nfev, "max_nfev", tol)
    na, nb, nc, delay, dt = o.na, o.nb, o.nc, o.delay, o.dt
    if theta0 is not None and nc:  # ignored for nc = 0
        theta0 = check_theta0(theta0, o.n_params)
    if theta0 is None and smaller_c and nc >= 2:
        theta0 = _smaller_c_theta(u, y, na, nb, nc, delay, dt, radius, max_nfev, tol)
    model = _armax_fit(u, y, na, nb, nc, delay, dt, radius, max_nfev, tol, theta0)
    if not model.meta["stable"]:
        model.check(warn=True)  # EhssWarning: an unstable model is never silent
    return model


def _smaller_c_theta(u: np.ndarray, y: np.ndarray, na: int, nb: int, nc: int, delay: int,
                     dt: float, radius: float, max_nfev: int, tol: float) -> np.ndarray:
    """θ of the fit with nc − 1 (started so itself, down to nc = 1), a zero appended."""
    theta0: np.ndarray | None = None
    for k in range(1, nc):
        m = _armax_fit(u, y, na, nb, k, delay, dt, radius, max_nfev, tol, theta0)
        theta0 = np.append(m.theta, 0.0)
    assert theta0 is not None  # nc ≥ 2: the loop ran
    return theta0


def _armax_fit(u: np.ndarray, y: np.ndarray, na: int, nb: int, nc: int, delay: int,
               dt: float, radius: float, max_nfev: int, tol: float,
               theta0: Any) -> ArmaxModel:
    """:func:`armax_pem` on checked arguments, without its warning."""
    su, sy = rms_scale(u), rms_scale(y)
    us, ys = u / su, y / sy
    dvec = theta_scale(na, nb, nc, su, sy)
    starts, k0 = _armax_starts(us, ys, na, nb, nc, delay, radius, max_nfev, tol)
    if theta0 is not None and nc:
        starts["theta0"] = _given_start(theta0, dvec, na, nb, nc, 0.95 * radius)
    problem = _Predictor(us, ys, na, nb, nc, delay, k0, radius)
    name, theta, losses, nfev_total = _best_start(problem, starts, max_nfev, tol)
    eps = problem.residual(theta)
    nv_s, cov_s = _covariance(problem.jacobian(theta), eps, theta.size)
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
                   delay, dt, meta, k0, warn=False)


def _armax_starts(us: np.ndarray, ys: np.ndarray, na: int, nb: int, nc: int, delay: int,
                  radius: float, max_nfev: int,
                  tol: float) -> tuple[dict[str, np.ndarray], int]:
    """The cheap starts on scaled data, by name, and the first sample of the loss.

    Extended least squares (C kept inside 0.95 radius), ARX with C = 1 and, when
    nc ≥ na, the output-error fit with C = F (white noise at the output).
    """
    phi, t, k0 = regression_matrix(us, ys, None, na, nb, 0, delay)
    k0 = max(k0, nc)
    n_ab = na + nb + 1
    starts: dict[str, np.ndarray] = {}
    arx = np.zeros(n_ab + nc)
    arx[:n_ab] = np.linalg.lstsq(phi, t, rcond=None)[0]
    if nc:
        els = els_theta(us, ys, na, nb, nc, delay)
        els[n_ab:] = stabilise(els[n_ab:], 0.95 * radius)
        starts["els"] = els
    starts["arx"] = arx
    if nc >= na:
        oe = _oe_fit(us, ys, na, nb, delay, radius, max_nfev, tol,
                     _oe_starts(us, ys, na, nb, delay, radius),
                     first_sample(na, nb, 0, delay))[0]
        starts["oe"] = np.concatenate([oe, oe[:na], np.zeros(nc - na)])
    return starts, k0


def _given_start(theta0: Any, dvec: np.ndarray, na: int, nb: int, nc: int,
                 radius: float) -> np.ndarray:
    """``theta0`` (physical units, checked) on the scaled data, its C stabilised inside
    radius."""
    t = theta0 / dvec
    n_ab = na + nb + 1
    t[n_ab:] = stabilise(t[n_ab:], radius)
    return t


def _best_start(problem: _Predictor, starts: dict[str, np.ndarray], max_nfev: int,
                tol: float) -> tuple[str, np.ndarray, dict[str, float], int]:
    """Fit from every start; the stable-A fit of lowest loss wins (earlier on a tie).

    A stable A beats any unstable one: a lower loss bought with a pole outside the unit
    circle is over-fitting (a near pole-zero-noise cancellation), not a model. For
    nc = 0 the loss is quadratic and the ARX start is already the optimum.
    """
    best = None
    losses = {}
    nfev_total = 0
    for name, x0 in starts.items():
        if problem.nc:
            x, cost, nfev = problem.fit(x0, max_nfev, tol)
        else:
            x, cost, nfev = x0, 0.5 * float(np.sum(problem.residual(x0) ** 2)), 0
        nfev_total += nfev
        losses[name] = 2.0 * cost / (problem.ys.size - problem.k0)
        if not np.all(np.isfinite(x)):
            continue
        key = (_radius(x[: problem.na]) >= 1.0, cost)
        if best is None or key < best[1]:
            best = (name, key, x)
    if best is None:
        raise IdentificationError("prediction-error minimisation diverged (non-finite θ)")
    return best[0], best[2], losses, nfev_total


# ------------------------------------------------------------------------------ OE
def _steiglitz_mcbride(us: np.ndarray, ys: np.ndarray, nf: int, nb: int, delay: int,
                       theta: np.ndarray, radius: float,
                       iterations: int = 8) -> np.ndarray:
    """Refilter u, y by 1/F and refit ARX (Steiglitz & McBride 1965): an OE start."""
    for _ in range(iterations):
        f = np.concatenate([[1.0], theta[:nf]])
        uf, yf = lfilter([1.0], f, us), lfilter([1.0], f, ys)
        phi, t, _ = regression_matrix(uf, yf, None, nf, nb, 0, delay)
        new = np.linalg.lstsq(phi, t, rcond=None)[0]
        new[:nf] = stabilise(new[:nf], start_radius(radius))
        if not np.all(np.isfinite(new)):
            break
        theta = new
    return theta


def _oe_starts(us: np.ndarray, ys: np.ndarray, nf: int, nb: int, delay: int,
               radius: float) -> dict[str, np.ndarray]:
    """The ARX fit and the Steiglitz–McBride iterations from it, on scaled data."""
    phi, t, _ = regression_matrix(us, ys, None, nf, nb, 0, delay)
    arx = np.linalg.lstsq(phi, t, rcond=None)[0]
    arx[:nf] = stabilise(arx[:nf], start_radius(radius))
    return {"arx": arx, "steiglitz_mcbride": _steiglitz_mcbride(us, ys, nf, nb, delay,
                                                                 arx.copy(), radius)}


def _oe_problem(us: np.ndarray, ys: np.ndarray, nf: int, nb: int, delay: int, radius: float,
                k0: int, records: list[tuple[np.ndarray, np.ndarray, float]]
                ) -> _Predictor | _Joint:
    """The OE problem of a scaled record, its loss counted from sample ``k0``, joined
    with further scaled ``records`` (u, y, weight), each counted from its first sample
    that has a full regressor."""
    main = _Predictor(us, ys, nf, nb, 0, delay, k0, radius, oe=True)
    if not records:
        return main
    first = first_sample(nf, nb, 0, delay)
    return _Joint([main] + [_Predictor(u, y, nf, nb, 0, delay, first, radius, oe=True)
                            for u, y, _ in records],
                  [1.0] + [w for _, _, w in records])


def _oe_fit(us: np.ndarray, ys: np.ndarray, nf: int, nb: int, delay: int, radius: float,
            max_nfev: int, tol: float, starts: dict[str, np.ndarray], k0: int,
            records: list[tuple[np.ndarray, np.ndarray, float]] | None = None
            ) -> tuple[np.ndarray, str, dict[str, float], int, int]:
    """OE PEM on scaled data from each start, the loss counted from sample ``k0`` (and
    on further weighted ``records``); the lowest loss wins."""
    problem = _oe_problem(us, ys, nf, nb, delay, radius, k0, records or [])
    best = None
    losses = {}
    nfev_total = 0
    for name, x0 in starts.items():
        x, cost, nfev = problem.fit(x0, max_nfev, tol)
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
    theta0: Any = None,
    first: int = 0,
    records: Any = (),
    starts: Any = OE_STARTS,
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
    theta0 : array_like, optional
        A start [f1..f_nf, b0..b_nb] in physical units (e.g. a recursive estimate to
        refine): then the only start, instead of the ARX fit and the Steiglitz–McBride
        iterations. Its F is stabilised first, as every start's is.
    first : int
        The first sample whose error counts in the loss. The model runs from rest at
        the first sample of the record, so that a record cut out of a running test
        (whose output is not at rest there) can leave the model's start-up out of the
        fit; the samples before ``first`` still set its state.
    records : sequence of (u, y, weight)
        Further records of the same system, fitted together with ``u, y`` (several
        experiments, or a prior model's response to a probe that says what the data do
        not): each runs from rest at its own start, and its errors enter the loss
        times ``weight`` (> 0).
    starts : sequence of {"arx", "steiglitz_mcbride"}
        Without ``theta0``, the starts minimised from, each with ``max_nfev``
        evaluations (the lowest loss wins): the ARX fit, and the Steiglitz–McBride
        iterations from it. One of them halves the work.

    Returns
    -------
    ArmaxModel
        With a = c = F (na = nc = nf): A y = B u + A e is y = B/F u + e. ``covariance`` is
        σ² (JᵀJ)⁻¹ mapped onto θ = [f, b, f]; ``meta["method"]`` is "oe_pem".

    Examples
    --------
    An output error model's noise is white at the output:

    >>> import numpy as np
    >>> true = ArmaxModel(a=[1, -0.8], b=[0.5])
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal(3000)
    >>> y = true.simulate(u) + 0.1 * rng.standard_normal(3000)
    >>> m = oe_pem(u, y, nf=1, nb=0)
    >>> bool(abs(m.a[1] + 0.8) < 0.01) and bool(np.array_equal(m.a, m.c))
    True
    """
    o = ArmaxOrders(na=nf, nb=nb, nc=0, delay=delay, dt=dt)
    u, y = check_batch(u, y, o)
    radius = root_radius(radius)
    max_nfev, tol = solver_budget(max_nfev, "max_nfev", tol)
    nf, nb, delay, dt = o.na, o.nb, o.delay, o.dt
    su, sy = rms_scale(u), rms_scale(y)
    us, ys = u / su, y / sy
    dvec = np.ones(nf + nb + 1)
    dvec[nf:] = sy / su
    k0 = max(first_sample(nf, nb, 0, delay), check_int(first, "first", lo=0))
    if y.size - k0 <= dvec.size:
        raise DataError(f"first={first}: {y.size - k0} samples left in the loss for "
                        f"{dvec.size} parameters")
    names = _check_starts(starts)
    if theta0 is None:
        x0 = {k: v for k, v in _oe_starts(us, ys, nf, nb, delay, radius).items()
              if k in names}
    else:
        start = check_theta0(theta0, dvec.size) / dvec
        start[:nf] = stabilise(start[:nf], start_radius(radius))
        x0 = {"given": start}
    more = [(ur / su, yr / sy, w) for ur, yr, w in _check_records(records, o)]
    theta, name, losses, nfev_total, k0 = _oe_fit(us, ys, nf, nb, delay, radius, max_nfev,
                                                  tol, x0, k0, more)
    problem = _oe_problem(us, ys, nf, nb, delay, radius, k0, more)
    try:
        with np.errstate(over="ignore", invalid="ignore"):
            nv_s, cov_s = _covariance(problem.jacobian(theta), problem.residual(theta),
                                      theta.size)
    except np.linalg.LinAlgError:
        nv_s, cov_s = math.nan, np.full((theta.size, theta.size), math.nan)
    if not (np.isfinite(nv_s) and np.all(np.isfinite(cov_s))):
        raise IdentificationError("output-error minimisation diverged (its Jacobian "
                                  "overflows at the estimate)")
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


def _check_starts(starts: Any) -> tuple[str, ...]:
    if isinstance(starts, str):
        starts = (starts,)
    try:
        names = tuple(starts)
    except TypeError:
        names = ()
    if not names or not all(isinstance(k, str) and k in OE_STARTS for k in names):
        raise ParameterError(f"starts={starts!r} must name one or more of {OE_STARTS}")
    return names


def _check_records(records: Any, o: ArmaxOrders) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """Further records (u, y, weight), each checked as the main one, weight > 0."""
    out = []
    for k, record in enumerate(records):
        try:
            u, y, weight = record
        except (TypeError, ValueError):
            raise ParameterError(f"records[{k}] must be (u, y, weight)") from None
        u, y = check_batch(u, y, o)
        w = float(weight)
        if not (math.isfinite(w) and w > 0.0):
            raise ParameterError(f"records[{k}]: weight={weight!r} must be finite and > 0")
        out.append((u, y, w))
    return out


# ------------------------------------------------------------------------------ shared
def _finish(theta: np.ndarray, cov: np.ndarray, nv: float, na: int, nb: int, nc: int,
            delay: int, dt: float, meta: dict[str, Any], k0: int,
            warn: bool = True) -> ArmaxModel:
    if not np.all(np.isfinite(theta)):
        raise IdentificationError("the estimate does not fit float64 in physical units")
    radius = _radius(theta[:na])
    model = ArmaxModel.from_theta(
        theta, na=na, nb=nb, nc=nc, delay=delay, dt=dt, noise_variance=nv, covariance=cov,
        meta={**meta, "first_sample": int(k0), "stable": radius < 1.0,
              "max_pole_radius": radius},
    )
    if radius >= 1.0 and warn:
        model.check(warn=True)  # EhssWarning: an unstable model is never silent
    return model
