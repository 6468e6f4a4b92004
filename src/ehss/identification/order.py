"""Model order selection over a grid of ARMAX-family orders.

Each candidate is fitted with :func:`~ehss.identification.estimate`, the estimator that
identification uses (one ``method`` vocabulary: arx, armax, oe, rels, rml), so the pick
carries over: refitting it with the same method on the same data gives the same model
(every estimator is deterministic). With validation data the candidates are ranked by
their free-run (simulation) fit there, and AIC, FPE and MDL are extra columns; an
unstable candidate is never recommended. The one-step prediction errors ε on the
estimation data give the loss V = mean(ε²), and with p free parameters and N samples

.. math::

    \\mathrm{AIC} = \\ln V + 2p/N,\\quad
    \\mathrm{FPE} = V\\,\\frac{1 + p/N}{1 - p/N},\\quad
    \\mathrm{MDL} = \\ln V + p\\ln N / N .

The validation fit is fit = 100 (1 − ‖y − ŷ_sim‖ / ‖y − ȳ‖) with ŷ_sim the model's
noise-free response to the validation input from an initial state estimated by least
squares (MATLAB ``compare``'s default; or zero, see :func:`free_run_fit`); a simulation
that diverges scores −inf.
"""

from __future__ import annotations

import itertools
import math
import warnings
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.signal import lfilter

from ehss.errors import DataError, EhssWarning, IdentificationError, ParameterError
from ehss.identification.estimators import INITS, METHODS, estimate
from ehss.identification.model import ArmaxModel
from ehss.identification.rels import check_record

__all__ = ["OrderRow", "OrderSelection", "select_order", "fit_percent", "free_run_fit"]

_CRITERIA = ("aic", "fpe", "mdl", "fit")
_INITIAL = ("estimate", "zero")


@dataclass(frozen=True, kw_only=True)
class OrderRow:
    """One candidate of the grid."""

    na: int
    nb: int
    nc: int
    delay: int
    n_params: int
    loss: float
    aic: float
    fpe: float
    mdl: float
    fit: float = math.nan
    stable: bool = True
    max_pole_radius: float = 0.0


@dataclass(frozen=True, kw_only=True, eq=False)
class OrderSelection:
    """Result of :func:`select_order`.

    Attributes
    ----------
    table : tuple of OrderRow
        All candidates in grid order.
    best : OrderRow
        The candidate minimising ``criterion`` (maximising it for "fit").
    criterion : str
    model : ArmaxModel
        The fitted model of ``best``.
    method : str
        The estimator every candidate was fitted with.
    """

    table: tuple[OrderRow, ...]
    best: OrderRow
    criterion: str
    model: ArmaxModel
    method: str = "armax"


def fit_percent(y: np.ndarray, yhat: np.ndarray) -> float:
    """100 (1 − ‖y − ŷ‖/‖y − ȳ‖) (NRMSE fit, 100 is perfect)."""
    den = float(np.linalg.norm(y - np.mean(y)))
    if den == 0.0:
        return math.nan
    return 100.0 * (1.0 - float(np.linalg.norm(y - yhat)) / den)


def _candidates(name: str, v: Any, minimum: int) -> list[int]:
    vals = [v] if isinstance(v, (int, np.integer)) and not isinstance(v, bool) else list(v)
    if not vals:
        raise ParameterError(f"{name}={v!r} must list at least one order")
    for x in vals:
        if isinstance(x, bool) or not isinstance(x, (int, np.integer)) or x < minimum:
            raise ParameterError(f"{name}={v!r} must hold integers >= {minimum}")
    return [int(x) for x in vals]


def select_order(
    u: Any,
    y: Any,
    *,
    na: Iterable[int] | int,
    nb: Iterable[int] | int,
    nc: Iterable[int] | int,
    delay: Iterable[int] | int = 1,
    dt: float = 1.0,
    criterion: str | None = None,
    validation: tuple[Any, Any] | None = None,
    method: str = "armax",
    init: str = "batch",
    p0: float = 1e6,
    p0_c: float | None = None,
    forgetting: float = 1.0,
    fit_tolerance: float = 0.1,
    initial: str = "estimate",
) -> OrderSelection:
    """Fit every (na, nb, nc, delay) of the grid and pick the best stable one.

    Parameters
    ----------
    u, y : array_like, shape (n_samples,)
        Estimation data.
    na, nb, nc, delay : int or iterable of int
        Candidate orders (nc is ignored, and listed once, for "arx" and "oe").
    dt : float
        Sample period (s).
    criterion : {"fit", "aic", "fpe", "mdl"}, optional
        How the best is chosen; default "fit" (free-run fit on ``validation``) when
        validation data are given, else "aic". "fit" needs ``validation``.
    validation : (u_val, y_val), optional
        Held-out data (the end of the record or a separate record).
    method : {"arx", "armax", "oe", "rels", "rml"}
        The estimator, as in :func:`~ehss.identification.estimate` (default "armax").
    init : {"batch", "zero"}
        Start of "rels"/"rml", as in :func:`~ehss.identification.estimate`.
    p0, p0_c, forgetting : float
        α, α_c and λ of "rels"/"rml" (``p0``, ``p0_c`` with ``init="zero"`` only).
    fit_tolerance : float
        With ``criterion="fit"``, candidates within this many fit points of the best are
        taken as equally good and the one with the fewest parameters is picked (fit
        differences of a tenth of a point are within what one validation record can
        resolve; the smaller model generalises better).

    initial : {"estimate", "zero"}
        Initial state of the validation simulation, as in :func:`free_run_fit`.

    Returns
    -------
    OrderSelection
        Remaining ties go to the candidate listed first in the grid.

    Raises
    ------
    IdentificationError
        If no candidate is stable (with a finite score).
    """
    if criterion is None:
        criterion = "aic" if validation is None else "fit"
    if criterion not in _CRITERIA:
        raise ParameterError(f"criterion={criterion!r} must be one of {_CRITERIA}")
    if not isinstance(method, str) or method not in METHODS:
        raise ParameterError(f"method={method!r} must be one of {', '.join(METHODS)}")
    if not isinstance(init, str) or init not in INITS:
        raise ParameterError(f"init={init!r} must be one of {', '.join(INITS)}")
    if criterion == "fit" and validation is None:
        raise ParameterError("criterion='fit' needs validation=(u_val, y_val)")
    if initial not in _INITIAL:
        raise ParameterError(f"initial={initial!r} must be one of {', '.join(_INITIAL)}")
    tol = fit_tolerance
    if (isinstance(tol, bool) or not isinstance(tol, (int, float, np.integer, np.floating))
            or not (math.isfinite(tol) and tol >= 0)):
        raise ParameterError(f"fit_tolerance={fit_tolerance!r} must be a number >= 0")
    u, y = check_record(u, y)
    if validation is not None:
        uv, yv = check_record(*validation)
    ncs = _candidates("nc", nc, 0)
    if method in ("arx", "oe"):
        ncs = [0]
    grid = list(itertools.product(
        _candidates("na", na, 1), _candidates("nb", nb, 0), ncs,
        _candidates("delay", delay, 0),
    ))
    rows: list[OrderRow] = []
    models: list[ArmaxModel | None] = []
    for a_, b_, c_, d_ in grid:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", EhssWarning)  # unstable ones are scored
                m = estimate(u, y, method=method, na=a_, nb=b_, nc=c_, delay=d_, dt=dt,
                             init=init, p0=p0, p0_c=p0_c, forgetting=forgetting)
        except IdentificationError:  # a candidate that cannot be fitted is listed as failed
            p = a_ + b_ + 1 + c_
            rows.append(OrderRow(na=a_, nb=b_, nc=c_, delay=d_, n_params=p, loss=math.inf,
                                 aic=math.inf, fpe=math.inf, mdl=math.inf,
                                 fit=-math.inf if validation is not None else math.nan,
                                 stable=False, max_pole_radius=math.inf))
            models.append(None)
            continue
        rows.append(_score(m, u, y, None if validation is None else (uv, yv), initial))
        models.append(m)
    if not rows:  # pragma: no cover - _candidates forbids empty grids
        raise DataError(f"no candidate orders for {u.size} samples")
    key = (lambda r: -r.fit) if criterion == "fit" else (lambda r: getattr(r, criterion))
    ok = [i for i, r in enumerate(rows) if r.stable and math.isfinite(key(r))]
    if not ok:
        raise IdentificationError(
            f"none of the {len(rows)} candidate orders gives a stable model with method "
            f"{method!r}; try lower orders, another method or a longer record"
        )
    i = min(ok, key=lambda j: key(rows[j]))
    if criterion == "fit":
        near = [j for j in ok if rows[j].fit >= rows[i].fit - tol]
        i = min(near, key=lambda j: (rows[j].n_params, j))
    return OrderSelection(table=tuple(rows), best=rows[i], criterion=criterion,
                          model=models[i], method=method)


def _score(m: ArmaxModel, u: np.ndarray, y: np.ndarray,
           validation: tuple[np.ndarray, np.ndarray] | None, initial: str) -> OrderRow:
    """Loss, AIC, FPE, MDL on the estimation data and the free-run fit on validation."""
    k0 = max(m.na, m.nb + m.delay, m.nc)
    with np.errstate(all="ignore"):
        eps = (y - m.predict(u, y))[k0:]
        V = float(np.mean(eps * eps))
    N = eps.size
    # free parameters: an output-error model (c = a) has na + nb + 1
    oe = m.nc == m.na and m.nc > 0 and np.array_equal(m.a, m.c)
    p = m.na + m.nb + 1 + (0 if oe else m.nc)
    if not (math.isfinite(V) and V > 0):
        V = math.inf if not math.isfinite(V) else np.finfo(float).tiny
    radius = m.max_pole_radius()
    fit = math.nan
    if validation is not None:
        fit = free_run_fit(m, *validation, initial=initial)
    return OrderRow(
        na=m.na, nb=m.nb, nc=m.nc, delay=m.delay, n_params=p, loss=V,
        aic=math.log(V) + 2 * p / N,
        fpe=V * (1 + p / N) / (1 - p / N) if p < N else math.inf,
        mdl=math.log(V) + p * math.log(N) / N,
        fit=fit, stable=radius < 1.0, max_pole_radius=radius,
    )


def free_run_fit(model: ArmaxModel, u: Any, y: Any, *, initial: str = "estimate") -> float:
    """Simulation fit (%) of ``model`` on (u, y), as MATLAB's ``compare``.

    Parameters
    ----------
    model : ArmaxModel
    u, y : array_like, shape (n_samples,)
        Validation input and output (deviations from the operating point).
    initial : {"estimate", "zero"}
        "estimate" (default): the initial state of B/A is chosen by least squares to
        fit y (the model's free response is linear in it), so a record that does not
        start at rest is not penalised for its first transient; "zero": the model starts
        at rest.

    Returns
    -------
    float
        100 (1 − ‖y − ŷ‖/‖y − ȳ‖); −inf when the simulation diverges (non-finite, or
        larger than 1e6 times the output's range), so a diverging model is reported as
        such, never as a long number.
    """
    if initial not in _INITIAL:
        raise ParameterError(f"initial={initial!r} must be one of {', '.join(_INITIAL)}")
    u, y = check_record(u, y)
    bd = np.concatenate([np.zeros(model.delay), model.b])
    a = model.a
    with np.errstate(all="ignore"):
        ysim = lfilter(bd, a, u)
        if initial == "estimate":
            # ŷ = ŷ_0 + Σ z_j r_j with r_j the response to initial state e_j (lfilter's zi)
            n = max(a.size, bd.size) - 1
            basis = np.column_stack([lfilter(bd, a, np.zeros(u.size), zi=np.eye(n)[j])[0]
                                     for j in range(n)]) if n else np.zeros((u.size, 0))
            if n and np.all(np.isfinite(basis)) and np.all(np.isfinite(ysim)):
                z = np.linalg.lstsq(basis, y - ysim, rcond=None)[0]
                ysim = ysim + basis @ z
    span = float(np.max(np.abs(y - np.mean(y)))) or 1.0
    if not np.all(np.isfinite(ysim)) or float(np.max(np.abs(ysim))) > 1e6 * span:
        return -math.inf
    return fit_percent(y, ysim)
