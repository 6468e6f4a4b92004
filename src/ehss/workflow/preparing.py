"""From a measured record to estimation and validation data (:func:`prepare`)."""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from ehss import preprocess
from ehss._checks import as_record, check_band, check_fs
from ehss.errors import DataError, EhssWarning, ParameterError
from ehss.preprocess import Trend
from ehss.workflow.options import Preparation, or_default

__all__ = ["Prepared", "prepare", "judged_band", "HOLDOUT_EXCITATION_WARN"]

#: :func:`prepare` warns when the validation input's RMS (about its own mean) is below
#: this fraction of the estimation input's. A fit compares the output's excursions with
#: the model's errors; the excursions shrink with the input while the noise and the
#: errors of an imperfect model at other amplitudes do not, so an error that costs a
#: model 1 point of fit on the estimation data costs it 10 on validation data excited
#: 10 times less, and the 90 % acceptance no longer separates a good model from a bad
#: one: such a fit means nothing.
HOLDOUT_EXCITATION_WARN = 0.1

#: Fewest samples :func:`prepare` leaves the estimation and the validation data each.
MIN_SAMPLES = 32


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


def prepare(u: ArrayLike, y: ArrayLike, *, fs: float,
            preparation: Preparation | None = None) -> Prepared:
    """Split, detrend and decimate a record for identification and validation.

    Parameters
    ----------
    u, y : array_like, shape (n_samples,)
        Input and output as measured.
    fs : float
        Sample rate, Hz.
    preparation : Preparation, optional
        The held-out fraction or separate validation record, band of interest,
        detrending and decimation (default ``Preparation()``); the band's upper edge
        must be below fs/2, and a decimation factor must leave it inside the anti-alias
        filter's pass band.

    Returns
    -------
    Prepared

    Raises
    ------
    TypeError
        For a sample rate of the wrong type (the string ``"100"``) or settings that are
        not a :class:`Preparation`.
    ParameterError
        For a band above fs/2, or beyond the pass band of the decimation asked for.
    DataError
        For records too short to split or decimate.

    Examples
    --------
    >>> import numpy as np
    >>> u = np.random.default_rng(0).standard_normal(1000)
    >>> p = prepare(u, u, fs=100.0, preparation=Preparation(decimate=None))
    >>> p.u.size, p.u_val.size
    (700, 300)
    """
    u, y = as_record(u, y)
    fs = check_fs(fs)
    opts = or_default(preparation, Preparation, "preparation")
    _warn_if_clipped(y)
    from_input = opts.band_hz == "input"
    band_hz = None if from_input or opts.band_hz is None else check_band(opts.band_hz, fs=fs)
    ue, ye, uv, yv = _split(u, y, opts.validation)
    excitation = _excitation_ratio(ue, uv)
    ue, tu = preprocess.detrend(ue, opts.detrend)
    ye, ty = preprocess.detrend(ye, opts.detrend)
    # a separate record about the estimation's operating point too (its fit from there)
    op = (uv - tu.offset, yv - ty.offset) if opts.holdout is None else None
    uv, _ = preprocess.detrend(uv, opts.detrend)
    yv, tyv = preprocess.detrend(yv, opts.detrend)
    q = _decimation(opts.decimate, ue, ye, fs, band_hz)
    if opts.decimate == "auto":  # leave the validation data enough samples too
        q = max(1, min(q, uv.size // 256))
    if from_input:
        band_hz = _input_band(ue, fs, q)
    if q > 1:
        ue, ye = preprocess.decimate(ue, ye, q)
        uv, yv = preprocess.decimate(uv, yv, q)
        op = None if op is None else preprocess.decimate(*op, q)
    return Prepared(u=ue, y=ye, u_val=uv, y_val=yv, fs=fs, decimation=q,
                    detrend=opts.detrend, trend_u=tu, trend_y=ty, trend_y_val=tyv,
                    separate_validation=opts.holdout is None, holdout=opts.holdout,
                    band_hz=band_hz, u_val_op=None if op is None else op[0],
                    y_val_op=None if op is None else op[1],
                    validation_excitation=excitation)


def judged_band(prepared: Prepared) -> tuple[float, float]:
    """The band a model of ``prepared`` is judged over: the band of interest, or
    ``(0, 0.45 fs_model)``, up to :attr:`Prepared.untouched_hz`."""
    fs_m = prepared.fs_model
    lo, hi = prepared.band_hz if prepared.band_hz is not None else (0.0, 0.45 * fs_m)
    hi = min(hi, prepared.untouched_hz)
    return (lo if lo < hi else 0.0), hi


def _split(u: np.ndarray, y: np.ndarray, validation: float | tuple[np.ndarray, np.ndarray]
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Estimation and validation data: the record and a separate one, or the record and
    its held-out end."""
    if isinstance(validation, tuple):
        ue, ye, (uv, yv) = u, y, validation
    else:
        n_est = int(round(u.size * (1.0 - validation)))
        ue, ye, uv, yv = u[:n_est], y[:n_est], u[n_est:], y[n_est:]
    if ue.size < MIN_SAMPLES or uv.size < MIN_SAMPLES:
        raise DataError(f"{ue.size} estimation and {uv.size} validation samples are too few "
                        f"({MIN_SAMPLES} or more each)")
    return ue, ye, uv, yv


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


def _decimation(value: int | str | None, u: np.ndarray, y: np.ndarray, fs: float,
                band_hz: tuple[float, float] | None) -> int:
    """The factor asked for (checked by :class:`Preparation`), or the one ``"auto"``
    reads from the estimation data; a factor whose anti-alias filter would act on the
    band of interest is refused."""
    if value is None:
        return 1
    if value == "auto":
        return preprocess.auto_decimation(u, y, fs, band_hz=band_hz)
    q = int(value)
    edge = preprocess.DECIMATED_PASSBAND * fs / (2 * q)
    if band_hz is not None and band_hz[1] >= edge:
        raise ParameterError(f"decimating by {q} puts the band's upper edge {band_hz[1]:g} Hz "
                             f"beyond the anti-alias filter's pass band ({edge:g} Hz)")
    return q
