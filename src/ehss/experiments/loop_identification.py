"""Identify one closed loop from a test record and judge the model (PAPER.md §6).

The programme judges its models as ``ehss identify`` does, through :mod:`ehss.workflow`:
:func:`loop_record` prepares the record once (:func:`ehss.workflow.prepare`: the end held
out for validation, the mean removed from each part, no decimation, since compensation
plays drives at the control rate), and :func:`identify_and_check` fits a model on the
estimation part with RELS or RML (eqs 20–22, from the paper's start θ̂(0) = 0,
P(0) = αI), optionally behind the loop's known factors, and judges the complete model
with :func:`ehss.workflow.assess` and the one :class:`ehss.workflow.Acceptance`. The rest
of this module searches orders with them and replays the online estimator.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.signal import lfilter

from ehss.errors import IdentificationError
from ehss.frequency import FrequencyResponse, h1_estimate
from ehss.identification import ArmaxModel, RelsEstimator, rels
from ehss.identification.known import compose
from ehss.validation import FrfError, ValidationReport
from ehss.workflow import (
    Acceptance,
    Preparation,
    Prepared,
    Verdict,
    assess,
    prepare,
    validated_band,
)

__all__ = [
    "ACCEPTANCE",
    "Record",
    "ModelCheck",
    "loop_record",
    "identify_and_check",
    "check_model",
    "model_label",
    "simplest_passing",
    "convergence",
]

Orders = tuple[int, int, int, int]
Factors = tuple[np.ndarray, np.ndarray]

#: The acceptance the programme judges by: the library's default, the one ``ehss
#: identify`` applies.
ACCEPTANCE = Acceptance()


@dataclass(frozen=True, kw_only=True)
class Record:
    """One identification record, prepared for identification and validation.

    Attributes
    ----------
    prepared : Prepared
        From :func:`ehss.workflow.prepare`: the estimation part and the held-out end,
        each about its own mean. Models are fitted on ``prepared.u, prepared.y`` and
        judged on ``prepared.u_val, prepared.y_val``.
    u, y : ndarray, shape (n,)
        The whole record minus its means (for the figures and the online replay).
    n_ident : int
        Samples of the estimation part; the rest is held out.
    fs : float
        Sample rate (Hz).
    band_hz : (float, float)
        Band where the model is validated.
    frf : FrequencyResponse
        H1 estimate of the whole record (for the figures; the verdict uses the held-out
        end's own estimate, as ``ehss identify`` does).
    input_mean, output_mean : float
        The whole record's means.
    """

    prepared: Prepared
    u: np.ndarray
    y: np.ndarray
    n_ident: int
    fs: float
    band_hz: tuple[float, float]
    frf: FrequencyResponse
    input_mean: float
    output_mean: float


@dataclass(frozen=True, kw_only=True)
class ModelCheck:
    """One identified model and how it compares with the measurement.

    Attributes
    ----------
    label : str
        How it was obtained, e.g. ``"RELS (4,3,2,1)"``.
    model : ArmaxModel
        The complete closed-loop model, reference → measured output, with the operating
        point of its estimation data (``offsets``) and the band its validation confirmed
        (``band_hz``), as ``ehss identify`` writes them: ``ehss compensate`` reads both.
    report : ValidationReport
        :func:`ehss.workflow.assess` on the held-out end.
    verdict : Verdict
        The :class:`ehss.workflow.Acceptance`'s judgement of ``report``.
    simulated : ndarray
        The model's simulated output over the whole record from rest (operating point
        added), for the figures.
    """

    label: str
    model: ArmaxModel
    report: ValidationReport
    verdict: Verdict
    simulated: np.ndarray

    @property
    def error(self) -> FrfError:
        """Frequency-response error against the held-out end's estimate, in the band
        (:func:`ehss.workflow.assess` always compares over a band)."""
        err = self.report.frf_error
        if err is None:
            raise IdentificationError(f"{self.label}: validation compared no frequencies")
        return err

    @property
    def fit_pct(self) -> float:
        """The fit that judges the model: held-out free-run fit in the band."""
        return self.report.fit_pct

    @property
    def raw_fit_pct(self) -> float:
        """The held-out free-run fit without band-limiting."""
        return self.report.simulation_fit_pct

    @property
    def passes(self) -> bool:
        """The model meets the acceptance."""
        return self.verdict.accepted


def model_label(orders: Orders, known: bool = False, method: str = "rels") -> str:
    """``"RELS (4,3,2,1)"``, with a note when identified behind the known factors."""
    text = "{} ({},{},{},{})".format(method.upper(), *orders)
    return text + " behind the known generator and accelerometer coupling" if known else text


def loop_record(
    u_raw: np.ndarray, y_raw: np.ndarray, *, fs: float, band_hz: tuple[float, float],
    holdout: float,
) -> Record:
    """A closed-loop test record, prepared for identification as ``ehss identify`` does.

    Parameters
    ----------
    u_raw, y_raw : ndarray, shape (n,)
        Reference and measured output of the closed loop, in SI units.
    fs : float
        Sample rate (Hz).
    band_hz : (float, float)
        Validation band (the excitation band clipped to [0.5 Hz, 0.45 fs]).
    holdout : float
        Share of the record held out at its end.

    Returns
    -------
    Record
        ``prepared`` is ``prepare(u_raw, y_raw, fs=fs, preparation=Preparation(
        validation=holdout, band_hz=band_hz, detrend="mean", decimate=None))``: ``ehss
        identify --holdout HOLDOUT --band LO HI --detrend mean --decimate none`` on the
        same record.
    """
    prepared = prepare(u_raw, y_raw, fs=fs, preparation=Preparation(
        validation=holdout, band_hz=band_hz, detrend="mean", decimate=None))
    u_mean, y_mean = float(np.mean(u_raw)), float(np.mean(y_raw))
    u, y = np.asarray(u_raw, float) - u_mean, np.asarray(y_raw, float) - y_mean
    return Record(
        prepared=prepared,
        u=u,
        y=y,
        n_ident=int(prepared.u.size),
        fs=fs,
        band_hz=band_hz,
        # About 0.5 Hz resolution: the slow dynamics near the band's low end need it.
        frf=h1_estimate(u, y, fs, nperseg=int(2 ** round(np.log2(2.0 * fs)))),
        input_mean=u_mean,
        output_mean=y_mean,
    )


def identify_and_check(
    rec: Record,
    orders: Orders,
    *,
    forgetting: float,
    p0: float,
    method: str = "rels",
    known: Factors | None = None,
) -> ModelCheck:
    """Identify on the estimation part of ``rec`` and judge it as ``ehss identify`` does.

    Parameters
    ----------
    rec : Record
        From :func:`loop_record`.
    orders : (na, nb, nc, delay)
        ARMAX structure.
    forgetting, p0 : float
        RELS forgetting factor and initial covariance scale.
    method : {"rels", "rml"}
        Recursive estimator.
    known : (num, den), optional
        Known factors F(q) in ascending powers of q⁻¹: the input is filtered through
        them, the rest is identified and the complete model composed (and judged).

    Returns
    -------
    ModelCheck
    """
    p = rec.prepared
    u = p.u if known is None else lfilter(known[0], known[1], p.u)
    na, nb, nc, delay = orders
    model = rels(
        u, p.y, na=na, nb=nb, nc=nc, delay=delay, forgetting=forgetting, p0=p0,
        dt=1.0 / rec.fs, method=method,
    )
    if known is not None:
        model = compose(model, *known)
    return check_model(rec, model, label=model_label(orders, known is not None, method))


def check_model(rec: Record, model: ArmaxModel, *, label: str) -> ModelCheck:
    """Judge a complete model of the loop on the held-out end of ``rec``.

    :func:`ehss.workflow.assess` with :data:`ACCEPTANCE`: the verdict ``ehss identify``
    gives a model it fitted on the same record with the options of :func:`loop_record`.

    Parameters
    ----------
    rec : Record
        From :func:`loop_record`.
    model : ArmaxModel
        Reference → measured output about the operating point, at ``rec.fs``.
    label : str
        How it was obtained.

    Returns
    -------
    ModelCheck
        Its model carries the estimation data's operating point and the validated band
        (:func:`ehss.workflow.validated_band`; None when the validation compared fewer
        than two frequencies), as ``ehss identify`` writes them.
    """
    report, verdict = assess(model, rec.prepared, acceptance=ACCEPTANCE)
    model = replace(model, offsets=rec.prepared.offsets,
                    band_hz=validated_band(report, rec.fs))
    with np.errstate(over="ignore", invalid="ignore"):
        yhat = model.simulate(rec.u)
    yhat = np.where(np.isfinite(yhat), yhat, np.nan)  # a diverging simulation: not drawn
    return ModelCheck(label=label, model=model, report=report, verdict=verdict,
                      simulated=yhat + rec.output_mean)


def simplest_passing(
    rec: Record,
    orders: Orders,
    *,
    max_order: int,
    forgetting: float,
    p0: float,
    known: Factors | None = None,
) -> ModelCheck | None:
    """The simplest model that meets the acceptance, searching upwards from ``orders``.

    At each order na (from ``orders``' up to ``max_order``, nb = na − 1, the same delay)
    the candidates are, in this order: RELS with the given nc; RML (recursive maximum
    likelihood) with nc = na, which suits output-error records where RELS is biased; and,
    when ``known`` factors are given, both again behind them. ``orders`` itself with RELS
    is skipped (the caller has checked it).

    The other keywords are :func:`identify_and_check`'s.
    """
    na0, _, nc0, d0 = orders
    for na in range(na0, max_order + 1):
        for behind in [False, True] if known is not None else [False]:
            for method, nc in (("rels", nc0), ("rml", na)):
                if (na, behind, method) == (na0, False, "rels"):
                    continue
                candidate = identify_and_check(
                    rec, (na, na - 1, nc, d0), forgetting=forgetting, p0=p0, method=method,
                    known=known if behind else None,
                )
                if candidate.passes:
                    return candidate
    return None


def convergence(
    rec: Record, model: ArmaxModel, *, forgetting: float, p0: float, every: int = 10
) -> tuple[np.ndarray, np.ndarray]:
    """θ̂(k) of a model as the online estimator sees it on the estimation part (eqs 20–22).

    The streaming :class:`RelsEstimator` with the batch run's scaling replays the
    estimation part; it runs the same compiled step, so it ends on the batch estimate.

    Returns
    -------
    t : ndarray, shape (n_rows,)
        Time of each row (s).
    history : ndarray, shape (n_rows, n_params)
        θ̂ every ``every`` samples.
    """
    est = RelsEstimator(
        na=model.na,
        nb=model.nb,
        nc=model.nc,
        delay=model.delay,
        forgetting=forgetting,
        p0=p0,
        dt=model.dt,
        u_scale=float(model.meta["u_scale"]),
        y_scale=float(model.meta["y_scale"]),
        history_every=every,
    )
    est.update_many(rec.prepared.u, rec.prepared.y)
    history = np.asarray(est.history)
    return (np.arange(history.shape[0]) + 1) * every / rec.fs, history
