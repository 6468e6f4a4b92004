"""Model order selection over a grid of ARMAX orders with AIC, FPE and MDL.

For each candidate the model is fitted with :func:`~ehss.identification.armax_els`
(or :func:`~ehss.identification.rels`, RELS or RML), its one-step prediction errors ε on the
estimation data give the loss V = mean(ε²), and with p parameters and N samples

.. math::

    \\mathrm{AIC} = \\ln V + 2p/N,\\quad
    \\mathrm{FPE} = V\\,\\frac{1 + p/N}{1 - p/N},\\quad
    \\mathrm{MDL} = \\ln V + p\\ln N / N .

If validation data are given, the simulation fit (%) on them is reported too:
fit = 100 (1 − ‖y − ŷ_sim‖ / ‖y − ȳ‖).
"""

from __future__ import annotations

import itertools
import math
import warnings
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ehss.errors import DataError, EhssWarning, ParameterError
from ehss.identification.batch import armax_els
from ehss.identification.model import ArmaxModel
from ehss.identification.rels import check_record, rels

__all__ = ["OrderRow", "OrderSelection", "select_order", "fit_percent"]

_CRITERIA = ("aic", "fpe", "mdl", "fit")


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
    """

    table: tuple[OrderRow, ...]
    best: OrderRow
    criterion: str
    model: ArmaxModel


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
    criterion: str = "aic",
    validation: tuple[Any, Any] | None = None,
    method: str = "els",
    p0: float = 1e6,
    p0_c: float | None = None,
    forgetting: float = 1.0,
) -> OrderSelection:
    """Fit every (na, nb, nc, delay) of the grid and pick the best by ``criterion``.

    Parameters
    ----------
    u, y : array_like, shape (n_samples,)
        Estimation data.
    na, nb, nc, delay : int or iterable of int
        Candidate orders.
    dt : float
        Sample period (s).
    criterion : {"aic", "fpe", "mdl", "fit"}
        "fit" needs ``validation``.
    validation : (u_val, y_val), optional
        Held-out data for the simulation fit %.
    method : {"els", "rels", "rml"}
        Estimator: :func:`armax_els` (with PEM refinement), :func:`rels` with
        ``method="rels"`` (the paper's eqs 19–22) or with ``method="rml"`` (recursive
        maximum likelihood, for output-error-like disturbances; use nc = na).
    p0, p0_c : float
        Initial P of :func:`rels` (a, b part and c part) when ``method`` is "rels"
        or "rml".
    forgetting : float
        λ of :func:`rels` when ``method`` is "rels" or "rml" (default 1).
    """
    if criterion not in _CRITERIA:
        raise ParameterError(f"criterion={criterion!r} must be one of {_CRITERIA}")
    if method not in ("els", "rels", "rml"):
        raise ParameterError(f"method={method!r} must be 'els', 'rels' or 'rml'")
    if criterion == "fit" and validation is None:
        raise ParameterError("criterion='fit' needs validation=(u_val, y_val)")
    u, y = check_record(u, y)
    if validation is not None:
        uv, yv = check_record(*validation)
    grid = list(itertools.product(
        _candidates("na", na, 1), _candidates("nb", nb, 0), _candidates("nc", nc, 0),
        _candidates("delay", delay, 0),
    ))
    rows: list[OrderRow] = []
    models: list[ArmaxModel] = []
    n_total = u.size
    for a_, b_, c_, d_ in grid:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", EhssWarning)  # unstable candidates are scored
            if method == "els":
                m = armax_els(u, y, na=a_, nb=b_, nc=c_, delay=d_, dt=dt)
            else:
                m = rels(u, y, na=a_, nb=b_, nc=c_, delay=d_, dt=dt, p0=p0, p0_c=p0_c,
                         forgetting=forgetting, method=method)
        k0 = max(a_, b_ + d_, c_)
        eps = (y - m.predict(u, y))[k0:]
        N = eps.size
        p = a_ + b_ + 1 + c_
        V = float(np.mean(eps * eps))
        if not (math.isfinite(V) and V > 0):
            V = math.inf if not math.isfinite(V) else np.finfo(float).tiny
        fit = math.nan
        if validation is not None:
            with np.errstate(all="ignore"):
                fit = fit_percent(yv, m.simulate(uv))
            if not math.isfinite(fit):
                fit = -math.inf
        rows.append(OrderRow(
            na=a_, nb=b_, nc=c_, delay=d_, n_params=p, loss=V,
            aic=math.log(V) + 2 * p / N,
            fpe=V * (1 + p / N) / (1 - p / N) if p < N else math.inf,
            mdl=math.log(V) + p * math.log(N) / N,
            fit=fit,
        ))
        models.append(m)
    if not rows:  # pragma: no cover - _candidates forbids empty grids
        raise DataError(f"no candidate orders for {n_total} samples")
    if criterion == "fit":
        i = int(np.argmax([r.fit for r in rows]))
    else:
        i = int(np.argmin([getattr(r, criterion) for r in rows]))
    return OrderSelection(table=tuple(rows), best=rows[i], criterion=criterion, model=models[i])
