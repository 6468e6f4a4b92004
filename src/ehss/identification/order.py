"""Model order selection over a grid of ARMAX-family orders: the low-level search.

Each candidate is fitted with :func:`~ehss.identification.estimate`, the estimator that
identification uses (one ``method`` vocabulary: arx, armax, oe, rels, rml), so the pick
carries over: refitting it with the same method on the same data gives the same model
(every estimator is deterministic; an ARMAX candidate with nc ≥ 2 is also started from
the fit with one order less of C, which the grid hands it and a refit makes itself).
Given a ``score`` (a model's fit on validation data, higher is better) the candidates
are ranked by it, and AIC, FPE and MDL are extra columns; an unstable candidate is
never recommended. :func:`ehss.workflow.select_orders` is the search on a measured
record: it prepares the record as ``ehss identify`` does and scores each candidate
with the validation ``ehss identify`` reports. The one-step prediction errors ε on the
estimation data give the loss V = mean(ε²), and with p free parameters and N samples

.. math::

    \\mathrm{AIC} = \\ln V + 2p/N,\\quad
    \\mathrm{FPE} = V\\,\\frac{1 + p/N}{1 - p/N},\\quad
    \\mathrm{MDL} = \\ln V + p\\ln N / N .
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ehss._checks import as_record, check_choice, check_int_list, check_real
from ehss.errors import DataError, IdentificationError, ParameterError
from ehss.identification._grid import check_jobs, fit_grid
from ehss.identification.estimators import INITS, METHODS, estimate
from ehss.identification.model import ArmaxModel

__all__ = ["OrderRow", "OrderSelection", "select_order"]

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
    score: Callable[[ArmaxModel], float] | None = None,
    method: str = "armax",
    init: str = "batch",
    p0: float = 1e6,
    p0_c: float | None = None,
    forgetting: float = 1.0,
    fit_tolerance: float = 0.1,
    admissible: Callable[[ArmaxModel], bool] | None = None,
    jobs: int | None = None,
) -> OrderSelection:
    """Fit every (na, nb, nc, delay) of the grid and pick the best stable one.

    The candidates are fitted on ``jobs`` threads. With ``method="armax"`` a candidate
    with nc ≥ 2 waits for its neighbour with one order less of C when the grid has it
    and is also started from it (θ padded with a zero; the fit does the same by itself
    otherwise, :func:`~ehss.identification.pem.armax_pem` ``smaller_c``), keeping the
    better end: it never fits the estimation data worse than that neighbour. The result
    does not depend on ``jobs``.

    Parameters
    ----------
    u, y : array_like, shape (n_samples,)
        Estimation data.
    na, nb, nc, delay : int or iterable of int
        Candidate orders (nc is ignored, and listed once, for "arx" and "oe").
    dt : float
        Sample period (s).
    criterion : {"fit", "aic", "fpe", "mdl"}, optional
        How the best is chosen; default "fit" (the largest ``score``) when a score is
        given, else "aic". "fit" needs ``score``.
    score : callable, optional
        ``score(model) -> float``: the fit (percent, higher is better, −inf for a
        diverging simulation) of a fitted candidate on validation data, listed as
        ``fit``; :func:`ehss.workflow.select_orders` passes the free-run fit that
        ``ehss identify`` reports.
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
    admissible : callable, optional
        ``admissible(model) -> bool``, called after ``score``: when any stable candidate
        is admissible, the pick is made among those only (:func:`ehss.workflow.
        select_orders` passes its acceptance, so that a model that fails it is not
        recommended over one that meets it); when none is, among all stable ones.
    jobs : int, optional
        Threads fitting candidates side by side (default: the cores this process may
        use, ``os.sched_getaffinity``). ``score`` and ``admissible`` are called on the
        calling thread, in grid order.

    Returns
    -------
    OrderSelection
        Remaining ties go to the candidate listed first in the grid.

    Raises
    ------
    IdentificationError
        If no candidate is stable (with a finite score).
    """
    criterion, tol = _check_choices(criterion, score, method, init, fit_tolerance, admissible)
    u, y = as_record(u, y)
    ncs = [0] if method in ("arx", "oe") else check_int_list(nc, "nc", lo=0)
    grid = list(itertools.product(
        check_int_list(na, "na", lo=1), check_int_list(nb, "nb", lo=0), ncs,
        check_int_list(delay, "delay", lo=0),
    ))
    jobs = check_jobs(jobs)

    def fit(c: tuple[int, int, int, int], theta0: np.ndarray | None) -> ArmaxModel | None:
        try:
            return estimate(u, y, method=method, na=c[0], nb=c[1], nc=c[2], delay=c[3],
                            dt=dt, init=init, p0=p0, p0_c=p0_c, forgetting=forgetting,
                            theta0=theta0)
        except IdentificationError:  # a candidate that cannot be fitted is listed as failed
            return None

    rows: list[OrderRow] = []
    models: list[ArmaxModel | None] = []
    for i, m in fit_grid(grid, fit, jobs=jobs, neighbours=(method == "armax")):
        rows.append(_failed(grid[i], score) if m is None else _score(m, u, y, score))
        models.append(m)
    if not rows:  # pragma: no cover - check_int_list forbids empty grids
        raise DataError(f"no candidate orders for {u.size} samples")
    i = _pick(rows, models, criterion, tol, admissible, method)
    return OrderSelection(table=tuple(rows), best=rows[i], criterion=criterion,
                          model=_fitted(models[i]), method=method)


def _check_choices(
    criterion: str | None, score: Callable[[ArmaxModel], float] | None, method: str,
    init: str, fit_tolerance: float, admissible: Callable[[ArmaxModel], bool] | None,
) -> tuple[str, float]:
    """The criterion (by default "fit" with a score, else "aic") and the fit tolerance of
    :func:`select_order`, the other choices checked."""
    if criterion is None:
        criterion = "aic" if score is None else "fit"
    check_choice(criterion, "criterion", _CRITERIA)
    check_choice(method, "method", METHODS)
    check_choice(init, "init", INITS)
    if criterion == "fit" and score is None:
        raise ParameterError("criterion='fit' needs a score (the fit on validation data)")
    for name, f in (("score", score), ("admissible", admissible)):
        if f is not None and not callable(f):
            raise TypeError(f"{name} must be callable, not {type(f).__name__}")
    return criterion, check_real(fit_tolerance, "fit_tolerance", lo=0.0)


def _pick(rows: list[OrderRow], models: list[ArmaxModel | None], criterion: str, tol: float,
          admissible: Callable[[ArmaxModel], bool] | None, method: str) -> int:
    """Index of the best stable candidate (see :func:`select_order`)."""
    key = (lambda r: -r.fit) if criterion == "fit" else (lambda r: getattr(r, criterion))
    ok = [i for i, r in enumerate(rows) if r.stable and math.isfinite(key(r))]
    if not ok:
        raise IdentificationError(
            f"none of the {len(rows)} candidate orders gives a stable model with method "
            f"{method!r}; try lower orders, another method or a longer record"
        )
    if admissible is not None:
        passing = [j for j in ok if admissible(_fitted(models[j]))]
        ok = passing or ok
    i = min(ok, key=lambda j: key(rows[j]))
    if criterion == "fit":
        near = [j for j in ok if rows[j].fit >= rows[i].fit - tol]
        i = min(near, key=lambda j: (rows[j].n_params, j))
    return i


def _fitted(model: ArmaxModel | None) -> ArmaxModel:
    """A stable candidate's model (only a fitted candidate is stable)."""
    if model is None:  # pragma: no cover - a failed candidate is listed as unstable
        raise IdentificationError("a candidate listed as stable was not fitted")
    return model


def _failed(c: tuple[int, int, int, int],
            score: Callable[[ArmaxModel], float] | None) -> OrderRow:
    """The row of a candidate that could not be fitted."""
    na, nb, nc, d = c
    return OrderRow(na=na, nb=nb, nc=nc, delay=d, n_params=na + nb + 1 + nc, loss=math.inf,
                    aic=math.inf, fpe=math.inf, mdl=math.inf,
                    fit=-math.inf if score is not None else math.nan, stable=False,
                    max_pole_radius=math.inf)


def _score(m: ArmaxModel, u: np.ndarray, y: np.ndarray,
           score: Callable[[ArmaxModel], float] | None) -> OrderRow:
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
    fit = math.nan if score is None else float(score(m))
    return OrderRow(
        na=m.na, nb=m.nb, nc=m.nc, delay=m.delay, n_params=p, loss=V,
        aic=math.log(V) + 2 * p / N,
        fpe=V * (1 + p / N) / (1 - p / N) if p < N else math.inf,
        mdl=math.log(V) + p * math.log(N) / N,
        fit=fit, stable=radius < 1.0, max_pole_radius=radius,
    )
