"""Preparing a measured record for identification: detrending and decimation.

Measured records rarely arrive as the zero-mean, modestly sampled signals an ARMAX
estimator expects:

- :func:`detrend` removes the operating point (``"mean"``) or a drift (``"linear"``) and
  returns what it removed, so the model can carry its offsets
  (:attr:`ehss.identification.ArmaxModel.offsets`);
- :func:`decimate` lowers the sample rate of an oversampled record with a zero-phase,
  linear-phase anti-alias filter applied to input and output alike (the filter cancels
  from the input/output relation in its pass band);
- :func:`auto_decimation` chooses the factor from the band of interest or, without one,
  from the output's spectrum: an estimator sampling a loop at hundreds of times its
  bandwidth spends its fit on noise above the band, and its poles crowd at z = 1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.signal
from numpy.typing import ArrayLike

from ehss._checks import as_record, as_signal, check_fs, check_int
from ehss.errors import DataError, ParameterError

__all__ = [
    "CLIP_SHARE_WARN",
    "clipped_share",
    "DETRENDS",
    "Trend",
    "detrend",
    "decimate",
    "auto_decimation",
    "content_edge_hz",
    "excitation_band",
    "EXCITATION_LEVEL_DB",
    "TARGET_OVERSAMPLING",
    "DECIMATED_PASSBAND",
]

#: Accepted values of ``detrend``.
DETRENDS = ("mean", "linear", None)

#: :func:`auto_decimation` keeps the sample rate at least this many times the highest
#: frequency of interest (the band's upper edge, or the edge of the record's content):
#: the band then lies below a third of the new Nyquist frequency, well inside the
#: anti-alias filter's pass band, and a loop, whose content edge lies near twice its
#: bandwidth, is sampled at 10–20 times its bandwidth, the usual rule for identification.
TARGET_OVERSAMPLING = 6.0

#: Fraction of the decimated Nyquist frequency below which :func:`decimate` leaves the
#: record untouched: its anti-alias filter's gain is within 0.1 dB of 1 up to 0.86 of the
#: new Nyquist frequency and falls through its transition band above; 0.8 keeps a margin
#: of a few of a frequency-response estimate's bins. Above it the decimated record says
#: nothing reliable about the loop, and a model of it is not judged there.
DECIMATED_PASSBAND = 0.8

#: Shortest record :func:`decimate` leaves: an identification needs a few hundred samples.
_MIN_DECIMATED = 256


@dataclass(frozen=True, kw_only=True)
class Trend:
    """What :func:`detrend` removed from one signal: ``offset + slope·(k − k_mid)``.

    Attributes
    ----------
    kind : {"mean", "linear", None}
    offset : float
        Value of the removed line at the middle sample ``k_mid = (n − 1)/2`` (the mean of
        the signal for both kinds; 0 for None).
    slope : float
        Slope per sample (0 unless ``kind == "linear"``).
    """

    kind: str | None
    offset: float
    slope: float = 0.0


def detrend(x: ArrayLike, kind: str | None) -> tuple[np.ndarray, Trend]:
    """Remove the mean or a least-squares line from ``x``.

    Parameters
    ----------
    x : array_like, shape (n_samples,)
    kind : {"mean", "linear", None}
        None returns a copy of ``x``.

    Returns
    -------
    x_detrended : ndarray, shape (n_samples,)
    trend : Trend
        The removed line; for both kinds ``trend.offset`` is the mean of ``x`` (a least-
        squares line passes through the centroid).

    Examples
    --------
    >>> import numpy as np
    >>> x, tr = detrend(np.array([1.0, 2.0, 3.0, 4.0]), "linear")
    >>> np.allclose(x, 0), tr.offset, tr.slope
    (True, 2.5, 1.0)
    """
    x = as_signal(x, "x")
    if kind not in DETRENDS:
        raise ParameterError(f"detrend={kind!r} must be 'mean', 'linear' or None")
    if kind is None:
        return x.copy(), Trend(kind=None, offset=0.0)
    mean = float(np.mean(x))
    if kind == "mean" or x.size < 2:
        return x - mean, Trend(kind=kind, offset=mean)
    k = np.arange(x.size, dtype=np.float64) - (x.size - 1) / 2.0
    # least-squares line about the centroid: slope = Σ k (x − x̄) / Σ k²
    slope = float(np.dot(k, x - mean) / np.dot(k, k))
    return x - mean - slope * k, Trend(kind=kind, offset=mean, slope=slope)


def decimate(u: ArrayLike, y: ArrayLike, factor: int) -> tuple[np.ndarray, np.ndarray]:
    """Low-pass and keep every ``factor``-th sample of an input/output record.

    Parameters
    ----------
    u, y : array_like, shape (n_samples,)
    factor : int
        Decimation factor (1 returns copies).

    Returns
    -------
    u_dec, y_dec : ndarray, shape (ceil(n_samples / factor),)

    Notes
    -----
    Both signals go through the same linear-phase FIR low-pass (Kaiser window, β = 5, cut
    off at the new Nyquist frequency, :func:`scipy.signal.resample_poly`) whose delay is
    removed, so the filtering is zero-phase over the whole record and the input/output
    relation is unchanged below :data:`DECIMATED_PASSBAND` (0.8) of the new Nyquist
    frequency. The ends are
    extended by a straight line before filtering, which keeps the first and last samples
    free of filter transients for a record that is not at rest there.
    """
    u, y = as_record(u, y)
    factor = check_int(factor, "factor")
    if factor < 1:
        raise ParameterError(f"decimation factor {factor} must be >= 1")
    if factor == 1:
        return u.copy(), y.copy()
    if -(-u.size // factor) < _MIN_DECIMATED:
        raise DataError(f"decimating {u.size} samples by {factor} leaves fewer than "
                        f"{_MIN_DECIMATED}; use a smaller factor")
    kw = dict(up=1, down=factor, padtype="line")
    return (scipy.signal.resample_poly(u, **kw), scipy.signal.resample_poly(y, **kw))


def content_edge_hz(x: ArrayLike, fs: float, *, fraction: float = 0.99) -> float:
    """Frequency below which ``fraction`` of the (mean-removed) power of ``x`` lies, Hz.

    The power spectrum is a Welch estimate with segments of an eighth of the record
    (Hann, half overlap), so the edge is resolved to about 8 fs / n.
    """
    x = as_signal(x, "x")
    fs = check_fs(fs)
    if not 0.0 < fraction < 1.0:
        raise ParameterError(f"{fraction=} must be in (0, 1)")
    nperseg = max(8, min(x.size, 2 ** int(math.log2(max(8, x.size // 8)))))
    f, p = scipy.signal.welch(x, fs=fs, nperseg=nperseg, detrend="constant")
    total = float(np.sum(p))
    if total <= 0.0:
        raise DataError("the signal is constant: it has no spectrum")
    cum = np.cumsum(p) / total
    return float(f[min(int(np.searchsorted(cum, fraction)), f.size - 1)])


#: :func:`excitation_band` keeps the frequencies where the input's power spectral density
#: is within this many dB of its peak: 1 % of the peak power per hertz. A band-limited
#: test's filter skirts fall through it within a fraction of an octave, so the band found
#: is the test's band; beyond it the input excites the loop 10 times (in amplitude) less
#: than in the band, and a model is not asked to hold there.
EXCITATION_LEVEL_DB = 20.0


def excitation_band(u: ArrayLike, fs: float, *, level_db: float = EXCITATION_LEVEL_DB
                    ) -> tuple[float, float]:
    """The band an input excites: where its power spectrum is within ``level_db`` of its
    peak, Hz.

    The power spectrum is the Welch estimate of :func:`content_edge_hz` (segments of an
    eighth of the record, so the edges are resolved to about 8 fs / n). The band runs
    from the lowest to the highest frequency at or above the level (gaps inside count as
    in the band); a lower edge in the first two bins is taken as 0 (DC), which the
    estimate cannot resolve from its first bin.

    Parameters
    ----------
    u : array_like, shape (n_samples,)
    fs : float
        Sample rate, Hz.
    level_db : float, default :data:`EXCITATION_LEVEL_DB`

    Returns
    -------
    (lo, hi) : (float, float)
        ``0 <= lo < hi <= fs / 2``.

    Raises
    ------
    DataError
        If the input is constant.

    Examples
    --------
    White noise excites everything; band-passed noise its pass band:

    >>> import numpy as np, scipy.signal
    >>> u = np.random.default_rng(0).standard_normal(40_000)
    >>> excitation_band(u, 1000.0)
    (0.0, 500.0)
    >>> sos = scipy.signal.butter(8, [2, 100], "bandpass", fs=1000.0, output="sos")
    >>> lo, hi = excitation_band(scipy.signal.sosfiltfilt(sos, u), 1000.0)
    >>> round(lo, 1), round(hi, 1)  # the skirts reach 20 dB a little outside 2-100 Hz
    (1.7, 111.8)
    """
    x = as_signal(u, "u")
    fs = check_fs(fs)
    if not (math.isfinite(level_db) and level_db > 0):
        raise ParameterError(f"{level_db=} must be a positive number of dB")
    nperseg = max(8, min(x.size, 2 ** int(math.log2(max(8, x.size // 8)))))
    f, p = scipy.signal.welch(x, fs=fs, nperseg=nperseg, detrend="constant")
    peak = float(np.max(p))
    if not peak > 0.0:
        raise DataError("the input is constant: it excites no band")
    kept = np.flatnonzero(p >= peak * 10.0 ** (-level_db / 10.0))
    lo = 0.0 if kept[0] <= 1 else float(f[kept[0]])
    hi = float(f[kept[-1]])
    if hi <= lo:  # a single line: the bin around it
        hi = min(lo + float(f[1]), fs / 2)
    return lo, hi


def auto_decimation(
    u: ArrayLike, y: ArrayLike, fs: float, *, band_hz: tuple[float, float] | None = None,
    target: float = TARGET_OVERSAMPLING,
) -> int:
    """Decimation factor that brings the sample rate down to about ``target`` times the
    highest frequency of interest (1 when the record is not oversampled).

    Parameters
    ----------
    u, y : array_like, shape (n_samples,)
    fs : float
        Sample rate, Hz.
    band_hz : (float, float), optional
        Band of interest. The highest frequency of interest is the lower of the edges
        below which 99 % of the input's and of the output's power lie
        (:func:`content_edge_hz`): above the input's edge the record says nothing about
        the loop, above the output's the loop hardly moves; with a band, its upper edge
        if that is higher.
    target : float, default :data:`TARGET_OVERSAMPLING`

    Returns
    -------
    int
        ``floor(fs / (target · f_hi))``, at least 1 and at most what leaves 256 samples.

    Examples
    --------
    A loop of about 8 Hz bandwidth, driven by a 0.1–15 Hz random test recorded at
    4 kHz, is decimated by 50 (to 80 Hz, ten times its bandwidth):

    >>> import numpy as np, scipy.signal
    >>> fs = 4000.0
    >>> u = np.random.default_rng(0).standard_normal(240_000)
    >>> u = scipy.signal.sosfiltfilt(scipy.signal.butter(4, [0.1, 15], "bandpass", fs=fs,
    ...                                                  output="sos"), u)
    >>> y = scipy.signal.lfilter(*scipy.signal.butter(2, 8.0, fs=fs), u)
    >>> auto_decimation(u, y, fs)
    50
    """
    u, y = as_record(u, y)
    fs = check_fs(fs)
    # where the record carries the loop's response: below the input's content edge (the
    # record says nothing above it) and the output's (the loop hardly moves above it)
    f_hi = min(content_edge_hz(u, fs), content_edge_hz(y, fs))
    if band_hz is not None:
        # the band of interest, but never below the loop's response: a model sampled
        # below its own dynamics places spurious poles
        f_hi = max(float(band_hz[1]), f_hi)
    if not (f_hi > 0 and math.isfinite(f_hi)):
        return 1
    q = int(fs // (float(target) * f_hi))
    q = min(q, u.size // _MIN_DECIMATED)
    return max(1, q)


#: Share of a measured output at one of its extreme values above which
#: :func:`ehss.workflow.prepare` warns that the record looks clipped.
CLIP_SHARE_WARN = 0.01


def clipped_share(x: np.ndarray) -> tuple[float, float]:
    """The share of samples of ``x`` at its maximum or at its minimum (the larger of the
    two), and that value.

    A measured response of a dynamic system with noise reaches its extremes at a few
    samples; a sensor's range, an ADC's full scale or a limiter holds it there for runs.
    """
    x = np.asarray(x, dtype=np.float64)
    if x.size == 0:
        return 0.0, math.nan
    top, bottom = float(np.max(x)), float(np.min(x))
    if top == bottom:
        return 1.0, top
    n_top, n_bottom = int(np.count_nonzero(x == top)), int(np.count_nonzero(x == bottom))
    return (n_top / x.size, top) if n_top >= n_bottom else (n_bottom / x.size, bottom)
