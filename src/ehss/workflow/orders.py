"""A grid of model orders searched the way :func:`~ehss.workflow.identify` fits and
validates one (:func:`select_orders`)."""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field

from numpy.typing import ArrayLike

from ehss.errors import DataError, EhssWarning
from ehss.identification import ArmaxModel, estimate
from ehss.identification.delay import DelayScan, scan_delays
from ehss.identification.order import OrderRow, OrderSelection, select_order
from ehss.validation import ValidationReport
from ehss.workflow.acceptance import Acceptance, Verdict
from ehss.workflow.identifying import assess
from ehss.workflow.options import (
    DEFAULT_MAX_NB,
    SAMPLES_PER_PARAMETER,
    Estimation,
    Evaluation,
    OrderGrid,
    Preparation,
    or_default,
)
from ehss.workflow.preparing import Prepared, prepare

__all__ = ["OrderSearch", "select_orders"]


@dataclass(frozen=True, kw_only=True, eq=False)
class OrderSearch:
    """Result of :func:`select_orders`.

    Attributes
    ----------
    selection : OrderSelection
        The table (AIC, FPE, MDL on the estimation data; ``fit`` the fit on the
        validation data that the verdict judges, :attr:`ValidationReport.fit_pct
        <ehss.validation.ValidationReport.fit_pct>`: the free-run simulation fit, in the
        band when one is given), the pick and its model, at the prepared rate.
    reports : tuple of (ValidationReport or None)
        Validation of each row's model (:func:`assess`); None where it could not be
        fitted.
    verdicts : tuple of (Verdict or None)
        Each row's verdict against the acceptance.
    prepared : Prepared
        The data every candidate was estimated and validated on.
    method, init, initial : str
        Estimator, start of the recursive ones, initial state of the validation simulation.
    delays : tuple of int
        The record delay (samples of the record, as given) of each row; the rows' own
        ``delay`` is at the prepared rate (``delay // prepared.decimation``).
    delay_scan : DelayScan or None
        When no delays were given: what the prepared estimation data said about the
        delay (:func:`ehss.identification.delay.scan_delays`, at the model's rate), from
        which the delays (and, without ``nb``, the nb) were chosen.
    """

    selection: OrderSelection
    reports: tuple[ValidationReport | None, ...] = field(repr=False)
    verdicts: tuple[Verdict | None, ...] = field(repr=False)
    prepared: Prepared = field(repr=False)
    method: str
    init: str
    initial: str
    delays: tuple[int, ...]
    delay_scan: DelayScan | None = None

    @property
    def best(self) -> OrderRow:
        """The pick (a stable candidate)."""
        return self.selection.best

    @property
    def best_index(self) -> int:
        """Row of the pick in :attr:`table`."""
        return next(i for i, r in enumerate(self.selection.table) if r is self.best)

    @property
    def best_orders(self) -> tuple[int, int, int, int]:
        """``(na, nb, nc, delay)`` of the pick, the delay in samples of the record: what
        :func:`identify` takes to refit it."""
        b = self.best
        return b.na, b.nb, b.nc, self.delays[self.best_index]

    @property
    def table(self) -> tuple[OrderRow, ...]:
        """All candidates in grid order."""
        return self.selection.table


def select_orders(
    u: ArrayLike,
    y: ArrayLike,
    *,
    fs: float,
    grid: OrderGrid | None = None,
    preparation: Preparation | None = None,
    estimation: Estimation | None = None,
    evaluation: Evaluation | None = None,
    acceptance: Acceptance | None = None,
    progress: Callable[[str], None] | None = None,
) -> OrderSearch:
    """Search a grid of orders the way :func:`~ehss.workflow.identify` fits and validates one.

    The record is prepared once (:func:`~ehss.workflow.prepare`: split or separate
    validation record, detrend, decimation); every candidate is fitted with
    :func:`ehss.identification.estimate` on the estimation data and validated with
    :func:`~ehss.workflow.assess` on the validation data; the candidates are ranked by
    the fit the verdict judges (:attr:`ehss.validation.ValidationReport.fit_pct`)
    through :func:`ehss.identification.select_order`, which never picks an unstable
    one, and picks among the candidates that meet the acceptance whenever any does.
    Refitting the pick with :func:`~ehss.workflow.identify` and the same settings gives
    the same model and fit.

    Parameters
    ----------
    u, y, fs
        As for :func:`~ehss.workflow.identify`: the record as measured, its rate in Hz.
    grid : OrderGrid, optional
        Candidate orders and how the pick is made (default ``OrderGrid()``). Delays are
        in samples of the record (as :func:`~ehss.workflow.identify` takes them), each
        divided by the decimation factor for the model. Without delays, they are read
        from the prepared estimation data (:func:`ehss.identification.delay.scan_delays`:
        the estimated delay and the one a sample of the model's rate shorter when the
        record supports it, else a few delays over the response's rise); without nb, 0
        to the nb that scan asks for (3 when the delay is supported). Every candidate
        must have at most one parameter per :data:`SAMPLES_PER_PARAMETER` estimation
        samples.
    preparation, estimation, evaluation, acceptance
        As for :func:`~ehss.workflow.identify`; the acceptance gives each row's verdict.
    progress : callable, optional
        Called with a line such as ``"(2,1,1,1): fit 98.7 %"`` after each candidate is
        validated (for a progress display).

    Returns
    -------
    OrderSearch

    Raises
    ------
    IdentificationError
        If no candidate is stable.
    TypeError
        For settings of the wrong type.
    ParameterError, DataError
        For bad settings or records, as :func:`~ehss.workflow.prepare`; DataError also
        for a grid whose largest candidate has more parameters than the estimation data
        support.
    """
    grid = or_default(grid, OrderGrid, "grid")
    est = or_default(estimation, Estimation, "estimation")
    acceptance = or_default(acceptance, Acceptance, "acceptance")
    evaluation = or_default(evaluation, Evaluation, "evaluation")
    prep = prepare(u, y, fs=fs, preparation=preparation)
    scorer = _Scorer(prep, acceptance, evaluation, progress)
    nc = (0,) if est.method in ("arx", "oe") else grid.nc
    _check_grid_size(prep, grid.na, grid.nb or (0,), nc)
    scan, delays = _delays(prep, grid.delay)
    nb = grid.nb if grid.nb is not None else _default_nb(prep, grid, scan)
    # delays at the model's rate (as identify rounds them), each with the first record
    # delay that gives it, so that identify's --delay refits the same model
    record_delay: dict[int, int] = {}
    for d in delays:
        record_delay.setdefault(int(d) // prep.decimation, int(d))
    sel = select_order(prep.u, prep.y, na=grid.na, nb=nb, nc=grid.nc,
                       delay=list(record_delay), dt=1.0 / prep.fs_model,
                       criterion=grid.criterion, score=scorer.score, method=est.method,
                       init=est.init, fit_tolerance=0.0, admissible=scorer.accepted)
    reports, verdicts = scorer.rows(sel)
    if grid.criterion == "fit":
        sel = _simplest_near_best(sel, verdicts, grid.error_tolerance, prep, est)
    return OrderSearch(selection=sel, reports=reports, verdicts=verdicts,
                       prepared=prep, method=est.method, init=est.init,
                       initial=evaluation.initial,
                       delays=tuple(record_delay[r.delay] for r in sel.table),
                       delay_scan=scan)


class _Scorer:
    """Validates each candidate of a search once (:func:`~ehss.workflow.assess`) and
    remembers its report and verdict, for the ranking and for the table."""

    def __init__(self, prepared: Prepared, acceptance: Acceptance, evaluation: Evaluation,
                 progress: Callable[[str], None] | None) -> None:
        self.prepared, self.acceptance, self.evaluation = prepared, acceptance, evaluation
        self.progress = progress
        self.assessed: dict[tuple[int, ...], tuple[ValidationReport, Verdict]] = {}

    def score(self, model: ArmaxModel) -> float:
        """The fit the verdict judges, of a candidate validated on the prepared data."""
        with warnings.catch_warnings():  # said once by prepare, not again per candidate
            warnings.simplefilter("ignore", EhssWarning)
            report, verdict = assess(model, self.prepared, acceptance=self.acceptance,
                                     evaluation=self.evaluation)
        self.assessed[(model.na, model.nb, model.nc, model.delay)] = (report, verdict)
        if self.progress is not None:
            self.progress(f"({model.na},{model.nb},{model.nc},{model.delay}): fit "
                          f"{report.fit_pct:.1f} %")
        return report.fit_pct

    def accepted(self, model: ArmaxModel) -> bool:
        return self.assessed[(model.na, model.nb, model.nc, model.delay)][1].accepted

    def rows(self, sel: OrderSelection) -> tuple[tuple[ValidationReport | None, ...],
                                                 tuple[Verdict | None, ...]]:
        """The report and verdict of each row of the table (None where it was not
        fitted)."""
        got = [self.assessed.get((r.na, r.nb, r.nc, r.delay)) if math.isfinite(r.loss)
               else None for r in sel.table]
        return (tuple(None if g is None else g[0] for g in got),
                tuple(None if g is None else g[1] for g in got))


def _delays(prep: Prepared, given: tuple[int, ...] | None
            ) -> tuple[DelayScan | None, tuple[int, ...]]:
    """The candidate delays in samples of the record: those given, or those the prepared
    estimation data's delay scan suggests (with the scan)."""
    if given is not None:
        return None, given
    try:
        scan = scan_delays(prep.u, prep.y)
    except DataError as exc:
        raise DataError(f"{exc}; give the candidate delays") from None
    return scan, tuple(d * prep.decimation for d in scan.delays)


def _default_nb(prep: Prepared, grid: OrderGrid, scan: DelayScan | None) -> tuple[int, ...]:
    """0-3, or what the delay scan asks for, as far as the record supports it."""
    top = DEFAULT_MAX_NB if scan is None else scan.max_nb
    room = prep.u.size // SAMPLES_PER_PARAMETER - max(grid.na) - 1 - max(grid.nc)
    return tuple(range(0, 1 + max(0, min(top, room))))


def _simplest_near_best(sel: OrderSelection, verdicts: tuple[Verdict | None, ...],
                        tolerance: float, prep: Prepared, est: Estimation) -> OrderSelection:
    """The candidate with the fewest parameters among those whose error 100 − fit is
    within ``(1 + tolerance)`` of the best's (of those that meet the acceptance whenever
    any does); its model refitted (every estimator is deterministic)."""
    rows = sel.table
    ok = [i for i, r in enumerate(rows) if r.stable and math.isfinite(r.fit)]
    pool = [i for i in ok if (v := verdicts[i]) is not None and v.accepted] or ok
    best_error = 100.0 - max(rows[i].fit for i in pool)
    near = [i for i in pool if 100.0 - rows[i].fit <= best_error * (1.0 + tolerance)]
    pick = rows[min(near, key=lambda i: (rows[i].n_params, i))]
    if pick is sel.best:
        return sel
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", EhssWarning)
        model = estimate(prep.u, prep.y, method=est.method, na=pick.na, nb=pick.nb,
                         nc=pick.nc, delay=pick.delay, dt=1.0 / prep.fs_model,
                         init=est.init)
    return dataclasses.replace(sel, best=pick, model=model)


def _check_grid_size(prep: Prepared, na: tuple[int, ...], nb: tuple[int, ...],
                     nc: tuple[int, ...]) -> None:
    """Refuse a grid whose largest candidate has more parameters than the estimation data
    have :data:`SAMPLES_PER_PARAMETER` samples for."""
    n = int(prep.u.size)
    largest = max(na) + max(nb) + 1 + max(nc)
    if largest * SAMPLES_PER_PARAMETER <= n:
        return
    rate = f" at the model's {prep.fs_model:g} Hz" if prep.decimation > 1 else ""
    held = (f"; the held-out fraction {prep.holdout:g} keeps {prep.u_val.size} of them "
            "for validation"
            if prep.holdout is not None and prep.holdout > 0.5 else "")
    raise DataError(
        f"the grid's largest candidate (na {max(na)}, nb {max(nb)}, nc {max(nc)}) has "
        f"{largest} parameters, more than {n} estimation samples{rate} support "
        f"({SAMPLES_PER_PARAMETER} a parameter: at most {n // SAMPLES_PER_PARAMETER})"
        f"{held}; search lower orders or give more estimation data")

