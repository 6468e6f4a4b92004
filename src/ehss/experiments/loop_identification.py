"""Identify one closed loop from a test record and judge the model (PAPER.md §6).

The record is taken about its operating point (RELS has no constant term) and split
into an estimation part and a held-out end (:func:`loop_record`); a model is identified
on the first with RELS or RML (eqs 20–22), optionally behind the loop's known factors,
and checked against the Hann-window H1 estimate and on the held-out end
(:func:`identify_and_check`). These two functions are the whole identification
workflow of the programme; the rest of this module searches orders with them and
replays the online estimator.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.signal import butter, lfilter, sosfiltfilt

from ehss.frequency import FrequencyResponse, h1_estimate
from ehss.identification import ArmaxModel, RelsEstimator, rels
from ehss.identification.known import compose
from ehss.validation import FrfError, frf_error, nrmse_fit

__all__ = [
    "MIN_COHERENCE",
    "MAX_MAG_ERROR_DB",
    "MAX_PHASE_ERROR_DEG",
    "MIN_FIT_PCT",
    "Record",
    "ModelCheck",
    "loop_record",
    "identify_and_check",
    "model_label",
    "simplest_passing",
    "convergence",
]

Orders = tuple[int, int, int, int]
Factors = tuple[np.ndarray, np.ndarray]

# Acceptance of PAPER.md §6 as set for this project: where γ² ≥ 0.9 in the band the
# model is within 1 dB and 5° of H1, and the held-out fit is at least 90 %.
MIN_COHERENCE = 0.9
MAX_MAG_ERROR_DB = 1.0
MAX_PHASE_ERROR_DEG = 5.0
MIN_FIT_PCT = 90.0


@dataclass(frozen=True, kw_only=True)
class Record:
    """One identification record about its operating point.

    Attributes
    ----------
    u, y : ndarray, shape (n,)
        Input and output minus their means.
    n_ident : int
        Samples of the estimation part; the rest is held out.
    fs : float
        Sample rate (Hz).
    band_hz : (float, float)
        Band where the model is validated.
    frf : FrequencyResponse
        H1 estimate of the whole record.
    y_band : ndarray, shape (n,)
        ``y`` low-passed (zero-phase) by ``lowpass``.
    lowpass : ndarray
        Second-order sections of the low-pass just above the band.
    input_mean, output_mean : float
        The operating point that was removed.
    """

    u: np.ndarray
    y: np.ndarray
    n_ident: int
    fs: float
    band_hz: tuple[float, float]
    frf: FrequencyResponse
    y_band: np.ndarray
    lowpass: np.ndarray
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
        The complete closed-loop model, reference → measured output.
    error : FrfError
        Against the H1 estimate, over the band, where γ² ≥ 0.9.
    fit_pct : float
        Held-out NRMSE fit of the simulated output, both signals low-passed (zero-phase)
        just above the band so that broadband sensor noise outside the identified band
        is not counted as model error.
    raw_fit_pct : float
        The same without the low-pass (bounded by the sensor noise level).
    simulated : ndarray
        The model's simulated output over the whole record (operating point added).
    """

    label: str
    model: ArmaxModel
    error: FrfError
    fit_pct: float
    raw_fit_pct: float
    simulated: np.ndarray

    @property
    def passes(self) -> bool:
        """Stable, and within the acceptance against H1 and on the held-out end."""
        err = self.error
        return (
            bool(self.model.is_stable())
            and err.n_points > 0
            and err.max_magnitude_db <= MAX_MAG_ERROR_DB
            and err.max_phase_deg <= MAX_PHASE_ERROR_DEG
            and self.fit_pct >= MIN_FIT_PCT
        )


def model_label(orders: Orders, known: bool = False, method: str = "rels") -> str:
    """``"RELS (4,3,2,1)"``, with a note when identified behind the known factors."""
    text = "{} ({},{},{},{})".format(method.upper(), *orders)
    return text + " behind the known generator and accelerometer coupling" if known else text


def loop_record(
    u_raw: np.ndarray, y_raw: np.ndarray, *, fs: float, band_hz: tuple[float, float],
    holdout: float,
) -> Record:
    """A closed-loop test record about its operating point, split for identification.

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
    """
    # Deviations from the operating point: RELS has no constant term.
    u_mean, y_mean = float(np.mean(u_raw)), float(np.mean(y_raw))
    u, y = u_raw - u_mean, y_raw - y_mean
    lowpass = butter(4, min(1.5 * band_hz[1], 0.45 * fs), fs=fs, output="sos")
    return Record(
        u=u,
        y=y,
        n_ident=int(round(u.size * (1.0 - holdout))),
        fs=fs,
        band_hz=band_hz,
        # About 0.5 Hz resolution: the slow dynamics near the band's low end need it.
        frf=h1_estimate(u, y, fs, nperseg=int(2 ** round(np.log2(2.0 * fs)))),
        y_band=sosfiltfilt(lowpass, y),
        lowpass=lowpass,
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
    """Identify on the estimation part of ``rec`` and check against the acceptance.

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
        them, the rest is identified and the complete model composed.

    Returns
    -------
    ModelCheck
    """
    n = rec.n_ident
    u = rec.u if known is None else lfilter(known[0], known[1], rec.u)
    na, nb, nc, delay = orders
    model = rels(
        u[:n], rec.y[:n], na=na, nb=nb, nc=nc, delay=delay, forgetting=forgetting, p0=p0,
        dt=1.0 / rec.fs, method=method,
    )
    if known is not None:
        model = compose(model, *known)
    # The model runs over the whole record from rest, so that the held-out part starts
    # from the state the estimation part left (no initial-condition transient).
    with np.errstate(over="ignore", invalid="ignore"):
        yhat = model.simulate(rec.u)
    if np.all(np.isfinite(yhat)):
        fit = nrmse_fit(rec.y_band[n:], sosfiltfilt(rec.lowpass, yhat)[n:])
        raw_fit = nrmse_fit(rec.y[n:], yhat[n:])
    else:  # an unstable model's simulation diverges: no fit at all
        fit = raw_fit = -math.inf
        yhat = np.where(np.isfinite(yhat), yhat, np.nan)
    return ModelCheck(
        label=model_label(orders, known is not None, method),
        model=model,
        error=frf_error(model, rec.frf, band_hz=rec.band_hz, min_coherence=MIN_COHERENCE),
        fit_pct=fit,
        raw_fit_pct=raw_fit,
        simulated=yhat + rec.output_mean,
    )


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
    est.update_many(rec.u[: rec.n_ident], rec.y[: rec.n_ident])
    history = np.asarray(est.history)
    return (np.arange(history.shape[0]) + 1) * every / rec.fs, history
