"""One identification workflow, from a measured record to a validated model and a verdict.

``ehss identify``, ``ehss order`` and the report all go through these functions, so a
model "meets the acceptance" in one sense only, the one :class:`Acceptance` defines:

1. :func:`prepare` splits the record into estimation and validation data (the held-out
   end, or a separate record), removes the operating point or a drift from each
   (:func:`ehss.preprocess.detrend`) and decimates an oversampled record
   (:func:`ehss.preprocess.decimate`, factor from :func:`ehss.preprocess.auto_decimation`);
2. :func:`identify` fits the model with :func:`ehss.identification.estimate`, validates it
   on the validation data (:func:`assess`, which serves models made otherwise too;
   :func:`ehss.validation.validate`: free-run fit from the
   least-squares initial state, k-step prediction fit, frequency-response error where the
   coherence is high, residual tests) and judges it with :meth:`Acceptance.judge`;
3. :func:`select_orders` prepares the record once as :func:`identify` does, fits every
   candidate of a grid of orders with the same estimator and ranks them by the same
   validation (:func:`assess`), so its pick validates the same when :func:`identify`
   refits it.

The model comes back with its operating point (``offsets``) and with ``band_hz`` set to
the span of frequencies over which the validation compared it with the data
(:func:`validated_band`: from DC when the comparison held from the estimate's first
bin). A decimated record gives a model at the decimated rate (its ``dt`` says so, and so
does :meth:`Identification.format`); :func:`ehss.compensate` applies it at the record's
rate.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ehss import preprocess
from ehss._checks import (
    as_record,
    check_band,
    check_fs,
    check_int,
    check_int_list,
    check_real,
)
from ehss.errors import DataError, EhssWarning, ParameterError
from ehss.frequency import FRF_METHODS
from ehss.identification import INITS, METHODS, ArmaxModel, estimate
from ehss.identification.delay import DelayScan, scan_delays
from ehss.identification.order import OrderRow, OrderSelection, select_order
from ehss.preprocess import DETRENDS, Trend
from ehss.validation import ValidationReport, fit_text, free_run, nrmse_fit, validate

__all__ = [
    "Acceptance",
    "Verdict",
    "Prepared",
    "Identification",
    "DEFAULT_METHOD",
    "prepare",
    "identify",
    "assess",
    "OrderSearch",
    "select_orders",
    "validated_band",
    "judged_band",
    "delay_text",
    "HOLDOUT_EXCITATION_WARN",
    "SAMPLES_PER_PARAMETER",
    "ERROR_TOLERANCE",
]

#: nb searched up to by :func:`select_orders` when the record supports its delay estimate
_DEFAULT_MAX_NB = 3

#: :func:`prepare` warns when the validation input's RMS (about its own mean) is below
#: this fraction of the estimation input's. A fit compares the output's excursions with
#: the model's errors; the excursions shrink with the input while the noise and the
#: errors of an imperfect model at other amplitudes do not, so an error that costs a
#: model 1 point of fit on the estimation data costs it 10 on validation data excited
#: 10 times less, and the 90 % acceptance no longer separates a good model from a bad
#: one: such a fit means nothing.
HOLDOUT_EXCITATION_WARN = 0.1

#: :func:`select_orders` refuses candidates with more parameters than the estimation
#: data have samples for at this many a parameter (the rule of ten samples a parameter:
#: beyond it the estimate's variance, p/N of the noise, swamps its fit).
SAMPLES_PER_PARAMETER = 10

#: :func:`select_orders` treats candidates whose validation error (100 − fit, percent)
#: is within this fraction of the best one's as equally good, and picks the one with the
#: fewest parameters. The relative standard error of an RMS over N independent samples
#: is 1/√(2N), 2 % at N = 1000; two candidates' errors on one record are correlated, so
#: 5 % is a difference that one validation record does not resolve. A tolerance on the
#: error and not on the fit: at 99.9 % a tenth of a point is 2.8 times the error.
ERROR_TOLERANCE = 0.05

#: Estimator used when none is named: ARMAX by prediction-error minimisation started from
#: extended least squares (a batch estimate, dependable where the recursive ones stall).
DEFAULT_METHOD = "armax"


# ------------------------------------------------------------------------- acceptance


@dataclass(frozen=True, kw_only=True)
class Acceptance:
    """What a validated model must show to be accepted: the only definition of it.

    Attributes
    ----------
    min_coherence : float, default 0.9
        Frequencies of the validation data's non-parametric estimate with a lower
        coherence are not compared (their own random error exceeds the tolerances: with
        8 averages the H1 error at γ² = 0.9 is already about 0.7 dB).
    max_magnitude_db : float, default 1.0
        Largest magnitude error against that estimate, dB.
    max_phase_deg : float, default 5.0
        Largest phase error, degrees.
    min_frf_points : int, default 3
        Fewest compared frequencies: with fewer the frequency response cannot confirm
        the model, and it is not accepted.
    min_fit_pct : float, default 90.0
        Smallest free-run simulation fit on the validation data, percent: in the band of
        interest when one is given (:func:`ehss.validation.band_fit`), raw otherwise.
    uncertainty_sigmas : float, default 2.0
        The frequency-response errors are judged after removing this many standard
        errors of the estimate itself at each point (from its coherence and averages,
        :class:`ehss.validation.FrfError`): an estimate from 8 averages at γ² = 0.9 is
        itself uncertain by 0.7 dB / 4.8°, and cannot show a model wrong by less. On a
        long, coherent record (γ² > 0.99, 10+ averages) this is a few hundredths of a dB.

    A model must also be stable (all poles strictly inside the unit circle) and its
    simulation must not diverge; these are not settings.
    """

    min_coherence: float = 0.9
    max_magnitude_db: float = 1.0
    max_phase_deg: float = 5.0
    min_frf_points: int = 3
    min_fit_pct: float = 90.0
    uncertainty_sigmas: float = 2.0

    def __post_init__(self) -> None:
        check_real(self.min_coherence, "min_coherence", lo=0.0, hi=1.0)
        for name in ("max_magnitude_db", "max_phase_deg"):
            check_real(getattr(self, name), name, lo=0.0, lo_open=True)
        check_int(self.min_frf_points, "min_frf_points", lo=1)
        check_real(self.uncertainty_sigmas, "uncertainty_sigmas", lo=0.0)
        check_real(self.min_fit_pct, "min_fit_pct", hi=100.0)

    def judge(self, report: ValidationReport) -> Verdict:
        """The verdict on a validation report (which must have a frequency-response error,
        i.e. was computed with a band)."""
        failed: list[str] = []
        if not report.stable:
            failed.append(f"unstable (max pole radius {report.max_pole_radius:.4f})")
        if report.diverged:
            failed.append("the simulation diverges")
        elif report.fit_pct < self.min_fit_pct:
            failed.append(f"fit {fit_text(report.fit_pct)} < {self.min_fit_pct:g} %")
        e = report.frf_error
        if e is None or e.n_points < self.min_frf_points:
            n = 0 if e is None else e.n_points
            failed.append(f"{n} frequencies with coherence >= {self.min_coherence:g} "
                          f"(at least {self.min_frf_points} needed to compare)")
        else:
            k = self.uncertainty_sigmas
            mag, ph = e.beyond_uncertainty(k)
            if mag > self.max_magnitude_db:
                failed.append(f"magnitude error {mag:.2f} dB beyond {k:g} standard errors "
                              f"of the estimate > {self.max_magnitude_db:g} dB")
            if ph > self.max_phase_deg:
                failed.append(f"phase error {ph:.1f} deg beyond {k:g} standard errors of "
                              f"the estimate > {self.max_phase_deg:g} deg")
        return Verdict(accepted=not failed, failed=tuple(failed), acceptance=self)

    def summary(self) -> dict[str, Any]:
        """Plain values for JSON."""
        return dataclasses.asdict(self)


@dataclass(frozen=True, kw_only=True)
class Verdict:
    """Whether a model meets the :class:`Acceptance`, and if not, why."""

    accepted: bool
    failed: tuple[str, ...]
    acceptance: Acceptance

    def format(self) -> str:
        """One line: ``verdict: meets the acceptance (...)`` or what failed."""
        a = self.acceptance
        rule = (f"stable, fit >= {a.min_fit_pct:g} %, frequency response within "
                f"{a.max_magnitude_db:g} dB / {a.max_phase_deg:g} deg (+ {a.uncertainty_sigmas:g}"
                f" standard errors of the estimate) where coherence >= {a.min_coherence:g}")
        if self.accepted:
            return f"verdict: meets the acceptance ({rule})"
        return f"verdict: does NOT meet the acceptance ({rule}): " + "; ".join(self.failed)

    def summary(self) -> dict[str, Any]:
        """Plain values for JSON."""
        return {"accepted": self.accepted, "failed": list(self.failed),
                "acceptance": self.acceptance.summary()}


# ---------------------------------------------------------------------------- prepare


@dataclass(frozen=True, kw_only=True, eq=False)
class Prepared:
    """Estimation and validation data ready for an estimator (see :func:`prepare`).

    Attributes
    ----------
    u, y : ndarray
        Estimation data, detrended and decimated.
    u_val, y_val : ndarray
        Validation data, detrended (with its own trend) and decimated alike.
    fs : float
        Sample rate of the data given, Hz.
    decimation : int
        Factor applied (1: none); the prepared data are at ``fs / decimation``.
    detrend : {"mean", "linear", None}
    trend_u, trend_y : Trend
        What was removed from the estimation data: the operating point of the model is
        ``(trend_u.offset, trend_y.offset)``.
    trend_y_val : Trend
        What was removed from the validation output (to plot it as measured).
    separate_validation : bool
        The validation data came from a separate record (else: the held-out end).
    holdout : float or None
        Fraction held out when it was not a separate record.
    band_hz : (float, float) or None
        The band of interest given.
    u_val_op, y_val_op : ndarray or None
        For a separate validation record: its data about the estimation data's operating
        point ``offsets`` (not its own), decimated alike; None for a held-out end.
    validation_excitation : float
        RMS of the validation input about its mean over the estimation input's
        (:data:`HOLDOUT_EXCITATION_WARN`).
    """

    u: np.ndarray = field(repr=False)
    y: np.ndarray = field(repr=False)
    u_val: np.ndarray = field(repr=False)
    y_val: np.ndarray = field(repr=False)
    fs: float
    decimation: int
    detrend: str | None
    trend_u: Trend
    trend_y: Trend
    trend_y_val: Trend
    separate_validation: bool
    holdout: float | None
    band_hz: tuple[float, float] | None
    u_val_op: np.ndarray | None = field(default=None, repr=False)
    y_val_op: np.ndarray | None = field(default=None, repr=False)
    validation_excitation: float = 1.0

    @property
    def untouched_hz(self) -> float:
        """Highest frequency at which the decimation left the record untouched, Hz: the
        anti-alias filter's pass band (:data:`ehss.preprocess.DECIMATED_PASSBAND` of the
        model's Nyquist frequency), or the record's Nyquist frequency without one."""
        if self.decimation == 1:
            return self.fs / 2
        return preprocess.DECIMATED_PASSBAND * self.fs_model / 2

    @property
    def fs_model(self) -> float:
        """Sample rate of the prepared data and of the model, Hz."""
        return self.fs / self.decimation

    @property
    def offsets(self) -> tuple[float, float]:
        """Operating point ``(u0, y0)`` of the estimation data."""
        return (self.trend_u.offset, self.trend_y.offset)


def prepare(
    u,
    y,
    *,
    fs: float,
    validation: float | tuple[Any, Any] = 0.3,
    band_hz: tuple[float, float] | None = None,
    detrend: str | None = "mean",
    decimate: int | str | None = "auto",
) -> Prepared:
    """Split, detrend and decimate a record for identification and validation.

    Parameters
    ----------
    u, y : array_like, shape (n_samples,)
        Input and output as measured (with their operating point).
    fs : float
        Sample rate, Hz.
    validation : float or (u_val, y_val), default 0.3
        A fraction in (0, 1): the end of the record kept for validation; or a separate
        validation record (same sample rate, same meaning of the columns).
    band_hz : (float, float) or "input", optional
        Band of interest (for the decimation factor); ``hi`` must be below fs/2.
        ``"input"``: the band the estimation input excites
        (:func:`ehss.preprocess.excitation_band`: where its power spectrum is within
        20 dB of its peak), read after the decimation factor is chosen from the record's
        content and kept below what the decimation leaves untouched; None when that is
        everything up to 0.45 of the model's rate. ``Prepared.band_hz`` holds the band
        read, and refitting with it and the factor chosen prepares the same data.
    detrend : {"mean", "linear", None}, default "mean"
        Removed from the estimation data and, separately, from the validation data (a
        record's operating point or drift is its own; MATLAB users do the same with
        ``detrend`` on each data set).
    decimate : "auto", int or None, default "auto"
        Decimation factor; ``"auto"`` uses :func:`ehss.preprocess.auto_decimation` on the
        estimation data (about 20× the highest frequency of interest), None or 1 none.

    Returns
    -------
    Prepared

    Raises
    ------
    TypeError
        For a sample rate, band or decimation of the wrong type (the string ``"100"``).
    ParameterError
        For a bad fraction, band (``lo >= hi``, above fs/2), detrend or decimation.
    DataError
        For records too short to split or decimate.
    """
    u, y = as_record(u, y)
    fs = check_fs(fs)
    _warn_if_clipped(y)
    if detrend not in DETRENDS:
        raise ParameterError(f"detrend={detrend!r} must be 'mean', 'linear' or None")
    from_input = isinstance(band_hz, str)
    if from_input and band_hz != "input":
        raise ParameterError(f"band_hz={band_hz!r} must be (lo, hi) in Hz, 'input' or None")
    if band_hz is not None and not from_input:
        band_hz = check_band(band_hz, fs=fs)
    holdout: float | None = None
    if isinstance(validation, tuple):
        if len(validation) != 2:
            raise ParameterError("validation must be a fraction or a pair (u_val, y_val)")
        uv, yv = as_record(*validation)
        ue, ye = u, y
        separate = True
    else:
        try:
            holdout = float(validation)
        except (TypeError, ValueError):
            raise ParameterError(f"validation={validation!r} must be a fraction in (0, 1) "
                                 "or a pair (u_val, y_val)") from None
        if not 0.0 < holdout < 1.0:
            raise ParameterError(f"validation fraction {holdout!r} must be in (0, 1)")
        n_est = int(round(u.size * (1.0 - holdout)))
        ue, ye, uv, yv = u[:n_est], y[:n_est], u[n_est:], y[n_est:]
        separate = False
    if ue.size < 32 or uv.size < 32:
        raise DataError(f"{ue.size} estimation and {uv.size} validation samples are too few "
                        "(32 or more each)")
    excitation = _excitation_ratio(ue, uv)
    ue, tu = preprocess.detrend(ue, detrend)
    ye, ty = preprocess.detrend(ye, detrend)
    # a separate record about the estimation's operating point too (its fit from there)
    op = (uv - tu.offset, yv - ty.offset) if separate else None
    uv, _ = preprocess.detrend(uv, detrend)
    yv, tyv = preprocess.detrend(yv, detrend)
    q = _decimation(decimate, ue, ye, fs, None if from_input else band_hz)
    if decimate == "auto":  # leave the validation data enough samples too
        q = max(1, min(q, uv.size // 256))
    if from_input:
        band_hz = _input_band(ue, fs, q)
    if q > 1:
        ue, ye = preprocess.decimate(ue, ye, q)
        uv, yv = preprocess.decimate(uv, yv, q)
        op = None if op is None else preprocess.decimate(*op, q)
    return Prepared(u=ue, y=ye, u_val=uv, y_val=yv, fs=fs, decimation=q, detrend=detrend,
                    trend_u=tu, trend_y=ty, trend_y_val=tyv, separate_validation=separate,
                    holdout=holdout, band_hz=band_hz,
                    u_val_op=None if op is None else op[0],
                    y_val_op=None if op is None else op[1],
                    validation_excitation=excitation)


# --------------------------------------------------------------------------- identify


@dataclass(frozen=True, kw_only=True, eq=False)
class Identification:
    """Result of :func:`identify`.

    Attributes
    ----------
    model : ArmaxModel
        At the prepared rate ``prepared.fs_model`` (``model.dt``), with ``offsets`` (the
        estimation data's operating point) and ``band_hz`` (the span of the frequencies
        compared in validation; None when none could be) set.
    report : ValidationReport
        Validation on the prepared validation data.
    verdict : Verdict
    prepared : Prepared
        The data the model was estimated and validated on, and how they were made.
    method : str
        Estimator (:data:`ehss.identification.METHODS`).
    orders : (int, int, int, int)
        ``(na, nb, nc, delay)`` as given, the delay in samples of the record; the model's
        own delay (``model.delay``) is ``delay // prepared.decimation`` samples at its rate.
    """

    model: ArmaxModel
    report: ValidationReport = field(repr=False)
    verdict: Verdict
    prepared: Prepared = field(repr=False)
    method: str
    orders: tuple[int, int, int, int]

    @property
    def accepted(self) -> bool:
        """The model meets the acceptance."""
        return self.verdict.accepted

    def summary(self) -> dict[str, Any]:
        """Plain values for JSON: settings, preprocessing, validation and verdict."""
        p = self.prepared
        return {
            "method": self.method,
            "orders": dict(zip(("na", "nb", "nc", "delay"), self.orders, strict=True)),
            "preprocessing": {
                "detrend": p.detrend,
                "offsets": {"input": p.trend_u.offset, "output": p.trend_y.offset},
                "slopes_per_s": {"input": p.trend_u.slope * p.fs,
                                 "output": p.trend_y.slope * p.fs},
                "decimation": p.decimation,
                "fs_data_hz": p.fs,
                "fs_model_hz": p.fs_model,
                "n_estimation": int(p.u.size),
                "n_validation": int(p.u_val.size),
                "validation": "separate record" if p.separate_validation else
                f"held-out end ({p.holdout:g} of the record)",
                "band_hz": None if p.band_hz is None else list(p.band_hz),
                "judged_band_hz": list(judged_band(p)),
                "validation_input_rms_ratio": p.validation_excitation,
            },
            "validation": self.report.summary(),
            "verdict": self.verdict.summary(),
        }

    def format(self) -> str:
        """The preprocessing, the validation and the verdict, for the terminal."""
        p = self.prepared
        lines = []
        if p.detrend is not None:
            lines.append(f"operating point removed ({p.detrend}): input {p.trend_u.offset!r}, "
                         f"output {p.trend_y.offset!r}")
        if p.decimation > 1:
            given = delay_text(self.orders[3], decimation=p.decimation, fs=p.fs)
            lines.append(f"decimated by {p.decimation} (zero-phase anti-alias filter): the "
                         f"model is at {p.fs_model:g} Hz, not the record's {p.fs:g} Hz; the "
                         f"given {given}; judged up to {p.untouched_hz:.4g} Hz, below which "
                         "the decimation left the record untouched")
        lines.append(self.report.format())
        if self.model.band_hz is not None:
            lo, hi = self.model.band_hz
            lines.append(f"validated band (coherence >= {self.verdict.acceptance.min_coherence:g}"
                         f"): {lo:.4g}-{hi:.4g} Hz")
        lines.append(self.verdict.format())
        return "\n".join(lines)


def identify(
    u,
    y,
    *,
    fs: float,
    orders: tuple[int, ...],
    method: str = DEFAULT_METHOD,
    init: str = "batch",
    validation: float | tuple[Any, Any] = 0.3,
    band_hz: tuple[float, float] | None = None,
    detrend: str | None = "mean",
    decimate: int | str | None = "auto",
    nperseg: int | None = None,
    frf_method: str = "auto",
    initial: str = "estimate",
    horizons: tuple[int, ...] = (1, 5),
    acceptance: Acceptance | None = None,
) -> Identification:
    """Identify an ARMAX-family model of a record, validate it and give the verdict.

    Parameters
    ----------
    u, y : array_like, shape (n_samples,)
        Input and output as measured.
    fs : float
        Sample rate, Hz.
    orders : (na, nb, nc) or (na, nb, nc, delay)
        Model orders; the delay (default 1) in samples of the record, divided by the
        decimation factor (rounded down) for the model.
    method : str, default :data:`DEFAULT_METHOD`
        One of :data:`ehss.identification.METHODS`.
    init : {"batch", "zero"}, default "batch"
        Start of "rels" and "rml" (:func:`ehss.identification.estimate`).
    validation : float or (u_val, y_val), default 0.3
        Held-out fraction or separate validation record (:func:`prepare`).
    band_hz : (float, float), optional
        Band of interest: where the frequency response is compared and the fit is scored.
        Default ``(0, 0.45 fs_model)``: everywhere the coherence allows.
    detrend, decimate
        See :func:`prepare`.
    nperseg : int, optional
        Segment length of the validation's frequency-response estimate, in samples at the
        model's rate. Default :func:`ehss.frequency.default_nperseg`.
    frf_method : {"auto", "welch", "dft"}, default "auto"
        See :func:`ehss.frequency.frf_estimate`.
    initial : {"estimate", "zero"}, default "estimate"
        Initial state of the validation simulation (:func:`ehss.validation.free_run`).
    horizons : tuple of int, default (1, 5)
        k-step prediction fits reported.
    acceptance : Acceptance, optional
        Default ``Acceptance()``.

    Returns
    -------
    Identification

    Raises
    ------
    TypeError
        For orders or settings of the wrong type (``na=1.5``).
    ParameterError
        For bad orders, method or settings.
    DataError
        For unusable records.

    Examples
    --------
    >>> import numpy as np, scipy.signal
    >>> rng = np.random.default_rng(1)
    >>> u = rng.standard_normal(4000)
    >>> y = 2.0 + scipy.signal.lfilter([0, 0.5], [1, -0.8], u) + 0.01 * rng.standard_normal(4000)
    >>> res = identify(u, y, fs=100.0, orders=(1, 0, 1, 1), decimate=None)
    >>> res.accepted, round(res.model.offsets[1], 1)
    (True, 2.0)
    """
    na, nb, nc, delay = _orders(orders)
    if method not in METHODS:
        raise ParameterError(f"method={method!r} must be one of {', '.join(METHODS)}")
    if init not in INITS:
        raise ParameterError(f"init={init!r} must be one of {', '.join(INITS)}")
    if frf_method not in FRF_METHODS:
        raise ParameterError(f"frf_method={frf_method!r} must be one of "
                             f"{', '.join(FRF_METHODS)}")
    if initial not in ("estimate", "zero"):
        raise ParameterError(f"initial={initial!r} must be 'estimate' or 'zero'")
    acceptance = Acceptance() if acceptance is None else acceptance
    if not isinstance(acceptance, Acceptance):
        raise TypeError(f"acceptance must be an Acceptance, not {type(acceptance).__name__}")
    if nperseg is not None:
        nperseg = check_int(nperseg, "nperseg", lo=1)
        if nperseg < 8:
            raise ParameterError(f"{nperseg=} must be >= 8")
    prep = prepare(u, y, fs=fs, validation=validation, band_hz=band_hz, detrend=detrend,
                   decimate=decimate)
    fs_m = prep.fs_model
    if nperseg is not None and nperseg > prep.u_val.size:
        raise ParameterError(f"{nperseg=} is longer than the validation data "
                             f"({prep.u_val.size} samples at {fs_m:g} Hz)")
    # the delay is given in samples of the record; at the decimated rate it is shorter
    # (rounded down, so the model never waits longer than the loop: b0 takes the rest)
    delay_m = delay // prep.decimation
    model = estimate(prep.u, prep.y, method=method, na=na, nb=nb, nc=nc, delay=delay_m,
                     dt=1.0 / fs_m, init=init)
    report, verdict = assess(model, prep, acceptance=acceptance, nperseg=nperseg,
                             frf_method=frf_method, initial=initial, horizons=horizons)
    model = dataclasses.replace(model, offsets=prep.offsets,
                                band_hz=validated_band(report, fs_m))
    return Identification(model=model, report=report, verdict=verdict, prepared=prep,
                          method=method, orders=(na, nb, nc, delay))


def validated_band(report: ValidationReport, fs_model: float) -> tuple[float, float] | None:
    """The band a validation confirmed a model over, as the model should carry it.

    The span of the frequencies where the model was compared with the record's
    frequency-response estimate (coherent and excited points, :func:`ehss.validation.
    frf_error`), with one exception at the low end: an estimate resolves nothing below
    its first frequency bin (``fs / nperseg``), so a comparison that already held there
    validates the model down to DC as far as the record can tell, and the band then
    starts at the lower edge of the band of interest (0 unless one was given). A record
    that did not excite its lowest bins (a 10–40 Hz test) keeps the lower edge the
    comparison found.

    Parameters
    ----------
    report : ValidationReport
    fs_model : float
        The model's sample rate, Hz (the band never reaches beyond half of it).

    Returns
    -------
    (lo, hi) or None
        None when fewer than two points were compared.
    """
    e = report.frf_error
    if e is None or e.n_points < 2 or not e.compared_hz[0] < e.compared_hz[1]:
        return None
    lo, hi = float(e.compared_hz[0]), min(float(e.compared_hz[1]), fs_model / 2)
    resolved = report.frf.freq_hz[report.frf.freq_hz > 0]
    if resolved.size and lo <= float(resolved[0]):
        lo = float(e.band_hz[0])  # the band of interest's lower edge (0 by default)
    return lo, hi


def assess(
    model: ArmaxModel,
    prepared: Prepared,
    *,
    acceptance: Acceptance | None = None,
    nperseg: int | None = None,
    frf_method: str = "auto",
    initial: str = "estimate",
    horizons: tuple[int, ...] = (1, 5),
) -> tuple[ValidationReport, Verdict]:
    """Validate any model on prepared validation data and judge it: what :func:`identify`
    does after estimating, for models made otherwise (printed in a paper, composed with a
    known part, fitted by another tool) or for each candidate of an order search.

    Parameters
    ----------
    model : ArmaxModel
        At the prepared rate (``model.dt == 1 / prepared.fs_model``), about the
        operating point (its input and output are deviations, as the prepared data).
    prepared : Prepared
        From :func:`prepare`; its band (or ``(0, 0.45 fs_model)``) is the band compared,
        up to the frequency the decimation left untouched (:attr:`Prepared.untouched_hz`):
        above it the anti-alias filter has acted on the record, and the model is not
        judged there.
    acceptance, nperseg, frf_method, initial, horizons
        As for :func:`identify`.

    Returns
    -------
    report : ValidationReport
        For a separate validation record, with ``operating_point_fit_pct``: the
        simulation fit of the record taken about the estimation data's operating point
        (the printed ``simulation_fit_pct`` takes it about its own mean).
    verdict : Verdict
    """
    acceptance = Acceptance() if acceptance is None else acceptance
    if not isinstance(acceptance, Acceptance):
        raise TypeError(f"acceptance must be an Acceptance, not {type(acceptance).__name__}")
    fs_m = prepared.fs_model
    if not math.isclose(model.dt, 1.0 / fs_m, rel_tol=1e-9):
        raise ParameterError(f"the model's dt={model.dt!r} s is not the prepared data's "
                             f"{1.0 / fs_m!r} s")
    report = validate(model, prepared.u_val, prepared.y_val, fs=fs_m,
                      band_hz=judged_band(prepared), holdout=None,
                      min_coherence=acceptance.min_coherence, horizons=horizons,
                      nperseg=nperseg, initial=initial, frf_method=frf_method)
    if not prepared.separate_validation:  # the held-out end: say how much came before it
        report = dataclasses.replace(report, n_estimation=int(prepared.u.size))
    elif prepared.u_val_op is not None and prepared.y_val_op is not None:
        with np.errstate(all="ignore"):
            yhat = free_run(model, prepared.u_val_op, prepared.y_val_op, initial=initial)
        report = dataclasses.replace(
            report, operating_point_fit_pct=nrmse_fit(prepared.y_val_op, yhat))
    return report, acceptance.judge(report)


def judged_band(prepared: Prepared) -> tuple[float, float]:
    """The band a model of ``prepared`` is judged over: the band of interest, or
    ``(0, 0.45 fs_model)``, up to :attr:`Prepared.untouched_hz`."""
    fs_m = prepared.fs_model
    lo, hi = prepared.band_hz if prepared.band_hz is not None else (0.0, 0.45 * fs_m)
    hi = min(hi, prepared.untouched_hz)
    return (lo if lo < hi else 0.0), hi


# ------------------------------------------------------------------------ order search


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
    u,
    y,
    *,
    fs: float,
    na,
    nb=None,
    nc,
    delay=None,
    method: str = DEFAULT_METHOD,
    init: str = "batch",
    validation: float | tuple[Any, Any] = 0.3,
    band_hz: tuple[float, float] | None = None,
    detrend: str | None = "mean",
    decimate: int | str | None = "auto",
    initial: str = "estimate",
    criterion: str = "fit",
    error_tolerance: float = ERROR_TOLERANCE,
    acceptance: Acceptance | None = None,
    progress: Callable[[str], None] | None = None,
) -> OrderSearch:
    """Search a grid of orders the way :func:`identify` fits and validates one.

    The record is prepared once (:func:`prepare`: split or separate validation record,
    detrend, decimation); every candidate is fitted with
    :func:`ehss.identification.estimate` on the estimation data and validated with
    :func:`assess` on the validation data; the candidates are ranked by the fit the
    verdict judges (:attr:`ehss.validation.ValidationReport.fit_pct`) through
    :func:`ehss.identification.select_order`, which never picks an unstable one, and
    picks among the candidates that meet the acceptance whenever any does. Refitting
    the pick with :func:`identify` and the same settings gives the same model and fit.

    Parameters
    ----------
    u, y : array_like, shape (n_samples,)
        Input and output as measured.
    fs : float
        Sample rate, Hz.
    na, nb, nc, delay : int or iterable of int
        Candidate orders; delays in samples of the record (as :func:`identify` takes
        them), each divided by the decimation factor for the model. Without ``delay``,
        the delays are read from the prepared estimation data
        (:func:`ehss.identification.delay.scan_delays`: the estimated delay and the one
        a sample of the model's rate shorter when the record supports it, else a few
        delays over the response's rise); without ``nb``, 0 to the nb that scan asks for
        (3 when the delay is supported). Every candidate must have at most one parameter
        per :data:`SAMPLES_PER_PARAMETER` estimation samples.
    method, init, validation, band_hz, detrend, decimate, initial
        As for :func:`identify`.
    criterion : {"fit", "aic", "fpe", "mdl"}, default "fit"
        How the pick is made: the validation fit, or an information criterion on the
        estimation data's one-step prediction errors.
    error_tolerance : float, default :data:`ERROR_TOLERANCE`
        With ``criterion="fit"``, candidates whose validation error ``100 − fit`` is at
        most ``(1 + error_tolerance)`` times the best one's are taken as equally good,
        and the one with the fewest parameters is picked (then the first in the grid),
        among those that meet the acceptance whenever any does.
    acceptance : Acceptance, optional
        For the verdict of each row (default ``Acceptance()``).
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
        For orders or settings of the wrong type (``na=[1.5]``).
    ParameterError, DataError
        For bad settings or records, as :func:`prepare`; DataError also for a grid whose
        largest candidate has more parameters than the estimation data support.
    """
    tol = check_real(error_tolerance, "error_tolerance", lo=0.0)
    if method not in METHODS:
        raise ParameterError(f"method={method!r} must be one of {', '.join(METHODS)}")
    if initial not in ("estimate", "zero"):
        raise ParameterError(f"initial={initial!r} must be 'estimate' or 'zero'")
    acceptance = Acceptance() if acceptance is None else acceptance
    if not isinstance(acceptance, Acceptance):
        raise TypeError(f"acceptance must be an Acceptance, not {type(acceptance).__name__}")
    delays = None if delay is None else check_int_list(delay, "delay", lo=0)
    prep = prepare(u, y, fs=fs, validation=validation, band_hz=band_hz, detrend=detrend,
                   decimate=decimate)
    q = prep.decimation
    na, nc = check_int_list(na, "na", lo=1), check_int_list(nc, "nc", lo=0)
    nb = None if nb is None else check_int_list(nb, "nb", lo=0)
    _check_grid_size(prep, na, nb or [0], [0] if method in ("arx", "oe") else nc)
    scan = None
    if delays is None:
        try:
            scan = scan_delays(prep.u, prep.y)
        except DataError as exc:
            raise DataError(f"{exc}; give the candidate delays") from None
        delays = [d * q for d in scan.delays]
    if nb is None:  # 0-3, or what the scan asks for, as far as the record supports it
        top = _DEFAULT_MAX_NB if scan is None else scan.max_nb
        room = prep.u.size // SAMPLES_PER_PARAMETER - max(na) - 1 - max(nc)
        nb = list(range(0, 1 + max(0, min(top, room))))
    # delays at the model's rate (as identify rounds them), each with the first record
    # delay that gives it, so that identify's --delay refits the same model
    record_delay: dict[int, int] = {}
    for d in delays:
        record_delay.setdefault(int(d) // q, int(d))
    assessed: dict[tuple[int, ...], tuple[ValidationReport, Verdict]] = {}

    def score(model: ArmaxModel) -> float:
        with warnings.catch_warnings():  # said once by prepare, not again per candidate
            warnings.simplefilter("ignore", EhssWarning)
            report, verdict = assess(model, prep, acceptance=acceptance, initial=initial)
        assessed[(model.na, model.nb, model.nc, model.delay)] = (report, verdict)
        if progress is not None:
            progress(f"({model.na},{model.nb},{model.nc},{model.delay}): fit "
                     f"{report.fit_pct:.1f} %")
        return report.fit_pct

    def accepted(model: ArmaxModel) -> bool:
        return assessed[(model.na, model.nb, model.nc, model.delay)][1].accepted

    sel = select_order(prep.u, prep.y, na=na, nb=nb, nc=nc, delay=list(record_delay),
                       dt=1.0 / prep.fs_model, criterion=criterion, score=score,
                       method=method, init=init, fit_tolerance=0.0,
                       admissible=accepted)
    reports, verdicts = [], []
    for r in sel.table:
        got = assessed.get((r.na, r.nb, r.nc, r.delay)) if math.isfinite(r.loss) else None
        reports.append(None if got is None else got[0])
        verdicts.append(None if got is None else got[1])
    if criterion == "fit":
        sel = _simplest_near_best(sel, verdicts, tol, prep, method=method, init=init)
    return OrderSearch(selection=sel, reports=tuple(reports), verdicts=tuple(verdicts),
                       prepared=prep, method=method, init=init, initial=initial,
                       delays=tuple(record_delay[r.delay] for r in sel.table),
                       delay_scan=scan)


def _simplest_near_best(sel: OrderSelection, verdicts, tolerance: float, prep: Prepared,
                        *, method: str, init: str) -> OrderSelection:
    """The candidate with the fewest parameters among those whose error 100 − fit is
    within ``(1 + tolerance)`` of the best's (of those that meet the acceptance whenever
    any does); its model refitted (every estimator is deterministic)."""
    rows = sel.table
    ok = [i for i, r in enumerate(rows) if r.stable and math.isfinite(r.fit)]
    pool = [i for i in ok if verdicts[i] is not None and verdicts[i].accepted] or ok
    best_error = 100.0 - max(rows[i].fit for i in pool)
    near = [i for i in pool if 100.0 - rows[i].fit <= best_error * (1.0 + tolerance)]
    pick = rows[min(near, key=lambda i: (rows[i].n_params, i))]
    if pick is sel.best:
        return sel
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", EhssWarning)
        model = estimate(prep.u, prep.y, method=method, na=pick.na, nb=pick.nb,
                         nc=pick.nc, delay=pick.delay, dt=1.0 / prep.fs_model, init=init)
    return dataclasses.replace(sel, best=pick, model=model)


def _check_grid_size(prep: Prepared, na: list[int], nb: list[int], nc: list[int]) -> None:
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


# ---------------------------------------------------------------------------- helpers
def delay_text(delay: int, *, decimation: int, fs: float) -> str:
    """A delay given in samples of the record, and what it is at the model's rate.

    ``"delay 6 samples at 1000 Hz = 2 samples of the model at 333.333 Hz"``; without
    decimation ``"delay 6 samples at 1000 Hz"``. The model's delay is rounded down (the
    model never waits longer than the loop; its first B tap takes the rest), and the
    text says so when it was.
    """
    d, q = int(delay), int(decimation)
    text = f"delay {d} sample{'' if d == 1 else 's'} at {fs:g} Hz"
    if q == 1:
        return text
    dm = d // q
    rounded = "" if d % q == 0 else " (rounded down)"
    return (f"{text} = {dm} sample{'' if dm == 1 else 's'} of the model at {fs / q:g} Hz"
            f"{rounded}")


def _input_band(u: np.ndarray, fs: float, q: int) -> tuple[float, float] | None:
    """The band the estimation input excites (:func:`ehss.preprocess.excitation_band`),
    up to what the decimation by ``q`` leaves untouched (and 0.45 of the model's rate);
    None when that is the whole default band anyway."""
    lo, hi = preprocess.excitation_band(u, fs)
    top = 0.45 * fs / q if q == 1 else min(0.45, preprocess.DECIMATED_PASSBAND / 2) * fs / q
    # strictly inside the pass band, so that the same band and factor prepare again
    top = float(np.nextafter(top, 0.0)) if q > 1 else top
    hi = min(hi, top)
    if lo == 0.0 and hi >= top:
        return None
    return (lo if lo < hi else 0.0), hi


def _excitation_ratio(u_est: np.ndarray, u_val: np.ndarray) -> float:
    """RMS of the validation input about its mean over the estimation input's; warns
    below :data:`HOLDOUT_EXCITATION_WARN`."""
    est = float(np.std(u_est))
    ratio = float(np.std(u_val)) / est if est > 0 else math.inf
    if ratio < HOLDOUT_EXCITATION_WARN:
        warnings.warn(
            f"the validation input's RMS is {100 * ratio:.3g} % of the estimation "
            f"input's (below {100 * HOLDOUT_EXCITATION_WARN:g} %): the validation data are "
            "barely excited, and a fit on them says nothing of the model; validate on a "
            "part of the record (or a record) excited like the estimation data",
            EhssWarning, stacklevel=3)
    return ratio


def _warn_if_clipped(y: np.ndarray) -> None:
    """Warn when the output sits at one extreme value for more than
    :data:`ehss.preprocess.CLIP_SHARE_WARN` of the record (and at least 5 samples)."""
    share, value = preprocess.clipped_share(y)
    if share > preprocess.CLIP_SHARE_WARN and share * y.size >= 5:
        warnings.warn(
            f"the output sits at {value:.6g} for {100 * share:.3g} % of the record: "
            "clipped by a sensor's range or a limit? A linear model of a clipped response "
            "is biased, and its fit flatters it; identify on a record within the range",
            EhssWarning, stacklevel=3)





def _decimation(value, u: np.ndarray, y: np.ndarray, fs: float,
                band_hz: tuple[float, float] | None) -> int:
    if value is None:
        return 1
    if isinstance(value, str):
        if value != "auto":
            raise ParameterError(f"decimate={value!r} must be 'auto', an integer >= 1 or None")
        return preprocess.auto_decimation(u, y, fs, band_hz=band_hz)
    q = check_int(value, "decimate", lo=1)
    if band_hz is not None and band_hz[1] >= 0.8 * fs / (2 * q):
        raise ParameterError(f"decimating by {q} puts the band's upper edge {band_hz[1]:g} Hz "
                             f"beyond the anti-alias filter's pass band "
                             f"({0.8 * fs / (2 * q):g} Hz)")
    return q


def _orders(orders) -> tuple[int, int, int, int]:
    try:
        vals = tuple(orders)
    except TypeError:
        raise ParameterError(f"orders={orders!r} must be (na, nb, nc) or (na, nb, nc, "
                             "delay)") from None
    if len(vals) not in (3, 4):
        raise ParameterError(f"orders={orders!r} must be (na, nb, nc) or (na, nb, nc, delay)")
    if len(vals) == 3:
        vals = (*vals, 1)
    out = []
    for name, v, lo in zip(("na", "nb", "nc", "delay"), vals, (1, 0, 0, 0), strict=True):
        out.append(check_int(v, name, lo=lo))
    return out[0], out[1], out[2], out[3]

