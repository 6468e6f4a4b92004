"""One entry point for every estimator of an ARMAX-family model from a whole record.

``method`` names the estimator; each returns an :class:`~ehss.identification.ArmaxModel`:

========  ==============================================================================
``arx``   least squares, A y = q^-d B u + e (``nc`` is ignored, C = 1)
``armax`` prediction-error minimisation started from extended least squares
          (:func:`~ehss.identification.pem.armax_pem`)
``oe``    output error y = q^-d B/F u + e by prediction-error minimisation
          (:func:`~ehss.identification.pem.oe_pem`); returned with a = c = F, so
          ``na`` is nf and ``nc`` is ignored (the model has nc = na)
``rels``  recursive extended least squares, the paper's eqs (19)–(22)
``rml``   recursive maximum likelihood (Ljung & Söderström)
========  ==============================================================================

Batch start of the recursive estimators (``init="batch"``, the default): the record is
first identified in batch (ARMAX PEM, or ARX when nc = 0), and the recursion then runs
over the record from that θ̂ with P(0) = (Σ ψ ψᵀ)⁻¹, the inverse information of the
batch estimate in the recursion's own metric (ψ the regressor of eq. 19 for RELS, the
1/Ĉ-filtered regressor for RML), adaptation held for the first samples while its
regressors fill and the record's initial transient decays (the recursion, like the
batch predictor, starts at rest). The recursion is then the second pass of a two-pass
estimate: it starts at the stationary point of its own loss with the gain it would have
had after one pass, so it cannot wander into the poor local minima that a start from
θ̂ = 0 with P(0) = α I falls into (RML on output-error records, RELS where 1/C − 1/2 is
not positive real), and it ends with the P that a streaming estimator needs to keep
tracking. ``init="zero"`` is the paper's start (θ̂(0) = 0, P(0) = α I).

The start cannot change where a recursion converges to: RELS's fixed point is the
prediction-error optimum only where 1/C − 1/2 is strictly positive real, so on
output-error records (C = A, lightly damped) RELS drifts away from the start even so;
use RML (or the batch "oe"/"armax") there.
"""

from __future__ import annotations

from typing import Any, Unpack

import numpy as np
from scipy.signal import lfilter

from ehss._checks import as_record, check_choice
from ehss.identification import _kernels as _k
from ehss.identification._common import (
    RecursionKeywords,
    RelsSettings,
    block_counters,
    model_from_state,
    new_state,
    regression_matrix,
    rms_scale,
    theta_scale,
)
from ehss.identification.batch import arx_ls
from ehss.identification.model import ArmaxModel
from ehss.identification.pem import armax_pem, oe_pem
from ehss.identification.rels import rels

__all__ = ["METHODS", "INITS", "estimate"]

METHODS = ("arx", "armax", "oe", "rels", "rml")
INITS = ("batch", "zero")
_C_RADIUS = 0.999  # as the batch PEM start keeps C: no projection at the first sample


def estimate(
    u: Any,
    y: Any,
    *,
    method: str,
    init: str = "batch",
    theta0: Any = None,
    **settings: Unpack[RecursionKeywords],
) -> ArmaxModel:
    """Fit an ARMAX-family model of orders (na, nb, nc) and delay to one record.

    Parameters
    ----------
    u, y : array_like, shape (n_samples,)
        Input and output (deviations from the operating point).
    method : {"arx", "armax", "oe", "rels", "rml"}
        The estimator (see the module's table).
    na, nb, nc : int
        Orders of A (nf for "oe"), B (nb + 1 coefficients) and C (ignored by "arx" and
        "oe").
    delay : int
        Input delay in samples.
    dt : float
        Sample period in seconds.
    init : {"batch", "zero"}
        Start of "rels"/"rml" (ignored by the batch methods): from the batch estimate
        with its inverse information as P(0) (default, see the module notes), or the
        paper's θ̂(0) = 0, P(0) = α I.
    forgetting, p0, p0_c : float
        λ, α and α_c of :func:`~ehss.identification.rels` ("rels"/"rml" only; ``p0``
        and ``p0_c`` only with ``init="zero"``).
    theta0 : array_like, optional
        One more start of the ARMAX prediction-error fit ("armax", and the batch start
        of "rels"/"rml"), in physical units (:func:`~ehss.identification.pem.armax_pem`);
        ignored by the other methods. For "armax" it replaces the fit with one order
        less of C that is otherwise made first (the order search passes the one it has).

    Raises
    ------
    TypeError
        For a ``method``, ``init``, order or setting of the wrong type.
    ParameterError
        For an unknown ``method`` or ``init``, or impossible orders or settings.
    DataError
        For a bad or too short record.

    Examples
    --------
    A noise-free record of a known first-order loop gives it back:

    >>> import numpy as np
    >>> true = ArmaxModel(a=[1, -0.8], b=[0.5])
    >>> u = np.random.default_rng(0).standard_normal(2000)
    >>> m = estimate(u, true.simulate(u), method="arx", na=1, nb=0, nc=0)
    >>> np.round(m.a, 6).tolist()
    [1.0, -0.8]
    """
    check_choice(method, "method", METHODS)
    check_choice(init, "init", INITS)
    # the orders, and λ, α, α_c of the recursions, checked once whatever the method
    s = RelsSettings(**settings, method="rml" if method == "rml" else "rels")
    if method == "arx":
        model = arx_ls(u, y, na=s.na, nb=s.nb, delay=s.delay, dt=s.dt)
        model.meta["stable"] = model.check(warn=True)  # an unstable fit is never silent
        return model
    if method == "armax":
        return armax_pem(u, y, na=s.na, nb=s.nb, nc=s.nc, delay=s.delay, dt=s.dt,
                         theta0=theta0, smaller_c=True)
    if method == "oe":
        return oe_pem(u, y, nf=s.na, nb=s.nb, delay=s.delay, dt=s.dt)
    if init == "zero":
        return rels(u, y, settings=s)
    start = (armax_pem(u, y, na=s.na, nb=s.nb, nc=s.nc, delay=s.delay, dt=s.dt, theta0=theta0)
             if s.nc else arx_ls(u, y, na=s.na, nb=s.nb, delay=s.delay, dt=s.dt))
    u, y = as_record(u, y)
    return _recursion_from(start, u, y, method=method, forgetting=s.forgetting)


def _recursion_from(start: ArmaxModel, u: np.ndarray, y: np.ndarray, *, method: str,
                    forgetting: float) -> ArmaxModel:
    """RELS/RML over the record from the batch estimate ``start`` (the module's notes).

    The regressor (and, for RML, the 1/Ĉ filter) starts at rest, so the first samples'
    prediction errors are the record's initial transient, not information: adaptation is
    held (the kernel's enabled flag, as :meth:`RelsEstimator.freeze`) while the
    regressors fill and that transient decays — max(na, nb + d, nc) samples plus the
    settling time of 1/Ĉ to 1e-3, at most a quarter of the record — then runs to the end.
    """
    na, nb, nc, d = start.na, start.nb, start.nc, start.delay
    n = na + nb + 1 + nc
    su, sy = rms_scale(u), rms_scale(y)
    us, ys = u / su, y / sy
    P0 = _start_information(u, y, start, filtered=(method == "rml"))
    theta_s = start.theta / theta_scale(na, nb, nc, su, sy)
    alpha = float(np.mean(np.diag(P0)))  # what a reset of P returns to (α I)
    settings = RelsSettings(na=na, nb=nb, nc=nc, delay=d, dt=start.dt, forgetting=forgetting,
                            p0=alpha, p0_c=alpha, trace_bound=float(np.trace(P0)),
                            c_radius=_C_RADIUS, method=method)
    block, views = new_state(settings.kernel(), theta_s)
    views.P[:] = P0
    r_c = float(np.max(np.abs(np.roots(start.c)))) if nc else 0.0
    settle = int(np.ceil(np.log(1e-3) / np.log(r_c))) if 0.0 < r_c < 1.0 else 0
    warm = min(max(na, nb + d, nc) + settle, u.size // 4)
    no_hist = np.empty((0, n))
    # adaptation held while the regressors fill (as RelsEstimator.freeze), then on
    _k.set_enabled(block, False)
    _k.rels_run(block, _k.record(us[:warm], ys[:warm]), no_hist, 1, True)
    _k.set_enabled(block, True)
    rec = _k.record(us[warm:], ys[warm:])
    _k.rels_run(block, rec, no_hist, 1, True)
    xi = rec[3]  # the residuals of the adapting part (warm < u.size // 4)
    nv_s = float(np.mean(np.square(xi[u.size // 2 - warm :])))
    counts = block_counters(block)
    counts.pop("n_samples", None)
    meta = {"method": method, "n_samples": int(u.size), "forgetting": forgetting,
            "init": "batch", "start_method": start.meta["method"], "warm_up": warm,
            "c_radius": _C_RADIUS, "u_scale": su, "y_scale": sy, **counts}
    model = model_from_state(views, settings, su, sy, nv_s, meta)
    model.check(warn=True)
    return model


def _start_information(u: np.ndarray, y: np.ndarray, start: ArmaxModel, *,
                       filtered: bool) -> np.ndarray:
    """(Σ ψψᵀ)⁻¹ at the batch estimate, on the RMS-normalised data the recursion uses.

    ψ(k) = [−y(k−1).., u(k−d).., ξ(k−1)..] with ξ the batch model's prediction errors
    (eq. 19's regressor); for RML ψ is filtered through 1/C, the gradient of ξ. A ridge
    of 1e-9 of the mean diagonal keeps P(0) positive definite when columns are
    dependent (an output-error start has C = A).
    """
    na, nb, nc, d = start.na, start.nb, start.nc, start.delay
    su, sy = rms_scale(u), rms_scale(y)
    us, ys = u / su, y / sy
    theta_s = start.theta / theta_scale(na, nb, nc, su, sy)
    a = np.concatenate([[1.0], theta_s[:na]])
    bd = np.concatenate([np.zeros(d), theta_s[na : na + nb + 1]])
    c = np.concatenate([[1.0], theta_s[na + nb + 1 :]])
    xi = lfilter([1.0], c, lfilter(a, [1.0], ys) - lfilter(bd, [1.0], us))
    psi, _, _ = regression_matrix(us, ys, xi, na, nb, nc, d)
    if filtered and nc:
        psi = lfilter([1.0], c, psi, axis=0)
    info = psi.T @ psi
    P = np.linalg.pinv(info)
    P = 0.5 * (P + P.T)
    return P + np.eye(P.shape[0]) * 1e-9 * max(float(np.mean(np.diag(P))), 1e-300)
