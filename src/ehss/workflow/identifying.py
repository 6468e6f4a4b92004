"""One model from a record: fit it, validate it, judge it (:func:`identify`, :func:`assess`)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ehss._checks import check_int
from ehss.errors import ParameterError
from ehss.identification import ArmaxModel, estimate
from ehss.validation import ValidationReport, free_run, nrmse_fit, validate
from ehss.workflow.acceptance import Acceptance, Verdict
from ehss.workflow.options import Estimation, Evaluation, Preparation, or_default
from ehss.workflow.preparing import Prepared, judged_band, prepare

__all__ = ["Identification", "identify", "assess", "validated_band", "delay_text"]


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
    u: ArrayLike,
    y: ArrayLike,
    *,
    fs: float,
    orders: tuple[int, ...],
    preparation: Preparation | None = None,
    estimation: Estimation | None = None,
    evaluation: Evaluation | None = None,
    acceptance: Acceptance | None = None,
) -> Identification:
    """Identify an ARMAX-family model of a record, validate it and give the verdict.

    Parameters
    ----------
    u, y, fs
        The record as measured and its sample rate in Hz, as :func:`prepare` takes them.
    orders : (na, nb, nc) or (na, nb, nc, delay)
        Model orders; the delay (default 1) in samples of the record, divided by the
        decimation factor (rounded down) for the model.
    preparation : Preparation, optional
        Validation data, band of interest, detrending and decimation (:func:`prepare`);
        the band is where the frequency response is compared and the fit is scored.
    estimation : Estimation, optional
        Estimator and start of the recursive ones (:func:`ehss.identification.estimate`).
    evaluation : Evaluation, optional
        How the model is validated (:func:`assess`); its ``nperseg`` must not exceed the
        validation data.
    acceptance : Acceptance, optional
        Default ``Acceptance()``.

    Returns
    -------
    Identification

    Raises
    ------
    TypeError
        For orders or settings of the wrong type (``na=1.5``, a dict for ``estimation``).
    ParameterError
        For bad orders, or settings that do not fit the record.
    DataError
        For unusable records.

    Examples
    --------
    >>> import numpy as np, scipy.signal
    >>> rng = np.random.default_rng(1)
    >>> u = rng.standard_normal(4000)
    >>> y = 2.0 + scipy.signal.lfilter([0, 0.5], [1, -0.8], u) + 0.01 * rng.standard_normal(4000)
    >>> res = identify(u, y, fs=100.0, orders=(1, 0, 1, 1),
    ...                preparation=Preparation(decimate=None))
    >>> res.accepted, round(res.model.offsets[1], 1)
    (True, 2.0)
    """
    na, nb, nc, delay = _orders(orders)
    est = or_default(estimation, Estimation, "estimation")
    evaluation = or_default(evaluation, Evaluation, "evaluation")
    acceptance = or_default(acceptance, Acceptance, "acceptance")
    prep = prepare(u, y, fs=fs, preparation=preparation)
    fs_m = prep.fs_model
    # the delay is given in samples of the record; at the decimated rate it is shorter
    # (rounded down, so the model never waits longer than the loop: b0 takes the rest)
    model = estimate(prep.u, prep.y, method=est.method, na=na, nb=nb, nc=nc,
                     delay=delay // prep.decimation, dt=1.0 / fs_m, init=est.init)
    report, verdict = assess(model, prep, acceptance=acceptance, evaluation=evaluation)
    model = dataclasses.replace(model, offsets=prep.offsets,
                                band_hz=validated_band(report, fs_m))
    return Identification(model=model, report=report, verdict=verdict, prepared=prep,
                          method=est.method, orders=(na, nb, nc, delay))


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
    evaluation: Evaluation | None = None,
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
    acceptance : Acceptance, optional
        Default ``Acceptance()``.
    evaluation : Evaluation, optional
        Default ``Evaluation()``; its ``nperseg`` must not exceed the validation data.

    Returns
    -------
    report : ValidationReport
        For a separate validation record, with ``operating_point_fit_pct``: the
        simulation fit of the record taken about the estimation data's operating point
        (the printed ``simulation_fit_pct`` takes it about its own mean).
    verdict : Verdict
    """
    acceptance = or_default(acceptance, Acceptance, "acceptance")
    ev = or_default(evaluation, Evaluation, "evaluation")
    fs_m = prepared.fs_model
    if not math.isclose(model.dt, 1.0 / fs_m, rel_tol=1e-9):
        raise ParameterError(f"the model's dt={model.dt!r} s is not the prepared data's "
                             f"{1.0 / fs_m!r} s")
    if ev.nperseg is not None and ev.nperseg > prepared.u_val.size:
        raise ParameterError(f"nperseg={ev.nperseg} is longer than the validation data "
                             f"({prepared.u_val.size} samples at {fs_m:g} Hz)")
    report = validate(model, prepared.u_val, prepared.y_val, fs=fs_m,
                      band_hz=judged_band(prepared), holdout=None,
                      min_coherence=acceptance.min_coherence, horizons=ev.horizons,
                      nperseg=ev.nperseg, initial=ev.initial, frf_method=ev.frf_method)
    if not prepared.separate_validation:  # the held-out end: say how much came before it
        report = dataclasses.replace(report, n_estimation=int(prepared.u.size))
    elif prepared.u_val_op is not None and prepared.y_val_op is not None:
        with np.errstate(all="ignore"):
            yhat = free_run(model, prepared.u_val_op, prepared.y_val_op, initial=ev.initial)
        report = dataclasses.replace(
            report, operating_point_fit_pct=nrmse_fit(prepared.y_val_op, yhat))
    return report, acceptance.judge(report)


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


def _orders(orders: Any) -> tuple[int, int, int, int]:
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

