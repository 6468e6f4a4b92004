"""Non-parametric frequency response: the H1 estimate and the coherence (Welch averages).

The paper validates each identified closed loop against a frequency response estimated
from the measured input and output with a Hanning window (Section 3 and Figs 13–15). This
module computes that estimate:

.. math::

    \\hat H_1(f) = \\frac{\\hat S_{uy}(f)}{\\hat S_{uu}(f)}, \\qquad
    \\hat\\gamma^2(f) = \\frac{|\\hat S_{uy}(f)|^2}{\\hat S_{uu}(f)\\,\\hat S_{yy}(f)},

where the spectra are Welch averages of windowed, overlapping segments
(:func:`scipy.signal.csd`, :func:`scipy.signal.welch`). H1 is unbiased by output noise; the
coherence says at which frequencies the output is linearly explained by the input.
"""

from __future__ import annotations

import math
import operator
from dataclasses import dataclass, field

import numpy as np
import scipy.signal

from ehss._checks import as_record
from ehss.errors import DataError, ParameterError

__all__ = ["FrequencyResponse", "h1_estimate", "default_nperseg", "n_segments"]

#: Fewest samples accepted by :func:`h1_estimate`.
MIN_SAMPLES = 16


@dataclass(frozen=True, kw_only=True, eq=False)
class FrequencyResponse:
    """A frequency response estimated from data.

    Attributes
    ----------
    freq_hz : ndarray, shape (n_freq,)
        Frequencies in Hz, increasing (0 excluded when the segments are detrended).
    response : ndarray of complex, shape (n_freq,)
        The estimate :math:`\\hat H_1(f)` (output units per input unit).
    coherence : ndarray, shape (n_freq,)
        Magnitude-squared coherence :math:`\\hat\\gamma^2(f) \\in [0, 1]`.
    n_averages : int
        Number of Welch segments averaged.
    nperseg : int
        Segment length in samples (frequency resolution ``fs / nperseg``).
    fs : float
        Sample rate in Hz.
    """

    freq_hz: np.ndarray = field(repr=False)
    response: np.ndarray = field(repr=False)
    coherence: np.ndarray = field(repr=False)
    n_averages: int
    nperseg: int
    fs: float

    def __post_init__(self) -> None:
        n = np.shape(self.freq_hz)
        if np.shape(self.response) != n or np.shape(self.coherence) != n:
            raise ParameterError(
                "freq_hz, response and coherence must have the same shape, got "
                f"{n}, {np.shape(self.response)}, {np.shape(self.coherence)}"
            )

    @property
    def resolution_hz(self) -> float:
        """Frequency spacing ``fs / nperseg`` in Hz."""
        return self.fs / self.nperseg

    @property
    def magnitude_db(self) -> np.ndarray:
        """Magnitude ``20 log10 |H|`` in dB (a zero response is shown as -400 dB)."""
        mag = np.abs(self.response)
        return 20.0 * np.log10(np.maximum(mag, 1e-20))

    @property
    def phase_deg(self) -> np.ndarray:
        """Phase in degrees, unwrapped along frequency (starts within ±180°)."""
        return np.degrees(np.unwrap(np.angle(self.response)))

    def band(self, lo_hz: float, hi_hz: float) -> FrequencyResponse:
        """The points with ``lo_hz <= f <= hi_hz`` (a new FrequencyResponse).

        Raises
        ------
        ParameterError
            If ``lo_hz > hi_hz`` or either is negative/non-finite.
        """
        lo_hz, hi_hz = _check_band((lo_hz, hi_hz))
        mask = (self.freq_hz >= lo_hz) & (self.freq_hz <= hi_hz)
        return FrequencyResponse(
            freq_hz=self.freq_hz[mask],
            response=self.response[mask],
            coherence=self.coherence[mask],
            n_averages=self.n_averages,
            nperseg=self.nperseg,
            fs=self.fs,
        )

    def to_columns(self) -> dict[str, np.ndarray]:
        """Columns for a CSV file: ``freq_hz, magnitude_db, phase_deg, coherence``."""
        return {
            "freq_hz": self.freq_hz,
            "magnitude_db": self.magnitude_db,
            "phase_deg": self.phase_deg,
            "coherence": self.coherence,
        }


def n_segments(n_samples: int, nperseg: int, noverlap: int) -> int:
    """Number of full Welch segments of ``nperseg`` samples with ``noverlap`` overlap."""
    if n_samples < nperseg:
        return 0
    return (n_samples - nperseg) // (nperseg - noverlap) + 1


def default_nperseg(n_samples: int, fs: float, *, min_averages: int = 8) -> int:
    """Default Welch segment length: a power of two close to ``fs`` (about 1 Hz
    resolution), halved until at least ``min_averages`` half-overlapping segments fit,
    but not below 16 samples.

    Examples
    --------
    >>> default_nperseg(20_000, 1000.0)
    1024
    >>> default_nperseg(5_000, 1000.0)
    1024
    >>> default_nperseg(2_000, 1000.0)
    256
    """
    nperseg = 2 ** max(4, round(math.log2(max(fs, 1.0))))
    while nperseg > 16 and (
        nperseg > n_samples or n_segments(n_samples, nperseg, nperseg // 2) < min_averages
    ):
        nperseg //= 2
    return nperseg


def h1_estimate(
    u,
    y,
    fs: float,
    *,
    nperseg: int | None = None,
    noverlap: int | None = None,
    window: str | tuple = "hann",
    detrend: str | bool = "constant",
) -> FrequencyResponse:
    """H1 frequency-response estimate and coherence from input ``u`` to output ``y``.

    Parameters
    ----------
    u, y : array_like, shape (n_samples,)
        Input (e.g. the reference of a closed loop) and output, finite, same length.
    fs : float
        Sample rate in Hz.
    nperseg : int, optional
        Segment length. Default :func:`default_nperseg`: a power of two giving about 1 Hz
        resolution and at least 8 averages when the record allows it.
    noverlap : int, optional
        Overlap between segments (default ``nperseg // 2``).
    window : str or tuple, default "hann"
        Window passed to :func:`scipy.signal.get_window` (the paper's Hanning window).
    detrend : {"constant", "linear", False}, default "constant"
        Detrending of each segment. When the segments are detrended the 0 Hz point carries
        no information and is left out.

    Returns
    -------
    FrequencyResponse

    Raises
    ------
    DataError
        If ``u``/``y`` are not 1-D, differ in length, are non-finite, are shorter than 16
        samples or ``nperseg``, or ``u`` has no power.
    ParameterError
        For an impossible ``fs``, ``nperseg``, ``noverlap`` or ``detrend``.

    Notes
    -----
    The auto- and cross-spectra are Welch averages (``scipy.signal.csd`` uses
    :math:`S_{xy} = \\overline{X} Y`), so

    .. math:: \\hat H_1 = \\hat S_{uy} / \\hat S_{uu}, \\quad
              \\hat\\gamma^2 = |\\hat S_{uy}|^2 / (\\hat S_{uu} \\hat S_{yy}).

    With :math:`n_d` averages the random error of :math:`|\\hat H_1|` is about
    :math:`\\sqrt{1-\\gamma^2} / (|\\gamma| \\sqrt{2 n_d})` (Bendat & Piersol). Bins where
    the input has exactly zero power get response 0 and coherence 0.

    Examples
    --------
    >>> import numpy as np, scipy.signal
    >>> u = np.random.default_rng(0).standard_normal(20_000)
    >>> y = scipy.signal.lfilter([0.2], [1.0, -0.8], u)
    >>> frf = h1_estimate(u, y, fs=1000.0)
    >>> frf.nperseg, frf.n_averages
    (1024, 38)
    """
    u, y = as_record(u, y)
    if u.size != y.size:
        raise DataError(f"u and y must have the same length, got {u.size} and {y.size}")
    fs = _check_fs(fs)
    n = u.size
    if n < MIN_SAMPLES:
        raise DataError(f"too few samples for a frequency response: {n} < {MIN_SAMPLES}")
    if nperseg is None:
        nperseg = default_nperseg(n, fs)
    else:
        nperseg = _as_int(nperseg, "nperseg")
        if nperseg < 4:
            raise ParameterError(f"{nperseg=} must be >= 4")
        if nperseg > n:
            raise DataError(f"{nperseg=} is longer than the record ({n} samples)")
    if noverlap is None:
        noverlap = nperseg // 2
    else:
        noverlap = _as_int(noverlap, "noverlap")
        if not 0 <= noverlap < nperseg:
            raise ParameterError(f"{noverlap=} must satisfy 0 <= noverlap < nperseg={nperseg}")
    if detrend not in ("constant", "linear", False):
        raise ParameterError(f"{detrend=} must be 'constant', 'linear' or False")
    if not np.any(u != u[0]):
        raise DataError("the input u is constant: it has no power to estimate a response")

    kw = dict(fs=fs, window=window, nperseg=nperseg, noverlap=noverlap, detrend=detrend)
    # S_uy = conj(U) Y, S_uu, S_yy: Welch averages of windowed segments.
    freq, s_uy = scipy.signal.csd(u, y, **kw)
    _, s_uu = scipy.signal.welch(u, **kw)
    _, s_yy = scipy.signal.welch(y, **kw)
    if detrend is not False:
        freq, s_uy, s_uu, s_yy = freq[1:], s_uy[1:], s_uu[1:], s_yy[1:]

    response = np.zeros(freq.shape, dtype=np.complex128)
    coherence = np.zeros(freq.shape, dtype=np.float64)
    ok = s_uu > 0
    # H1 = S_uy / S_uu
    response[ok] = s_uy[ok] / s_uu[ok]
    ok_y = ok & (s_yy > 0)
    # γ² = |S_uy|² / (S_uu S_yy), clipped to [0, 1] against rounding
    coherence[ok_y] = np.abs(s_uy[ok_y]) ** 2 / (s_uu[ok_y] * s_yy[ok_y])
    np.clip(coherence, 0.0, 1.0, out=coherence)
    return FrequencyResponse(
        freq_hz=freq,
        response=response,
        coherence=coherence,
        n_averages=n_segments(n, nperseg, noverlap),
        nperseg=nperseg,
        fs=fs,
    )


# ------------------------------------------------------------------------------- checks


def _as_int(x, name: str) -> int:
    try:
        return operator.index(x)
    except TypeError:
        raise ParameterError(f"{name}={x!r} must be an integer") from None


def _check_fs(fs) -> float:
    try:
        fs = float(fs)
    except (TypeError, ValueError):
        raise ParameterError(f"fs={fs!r} must be a number (Hz)") from None
    if not math.isfinite(fs) or fs <= 0:
        raise ParameterError(f"{fs=} must be a positive finite sample rate in Hz")
    return fs


def _check_band(band) -> tuple[float, float]:
    try:
        lo, hi = (float(v) for v in band)
    except (TypeError, ValueError):
        raise ParameterError(f"band={band!r} must be two numbers (lo_hz, hi_hz)") from None
    if not (math.isfinite(lo) and math.isfinite(hi)) or lo < 0 or lo > hi:
        raise ParameterError(f"band ({lo}, {hi}) Hz must satisfy 0 <= lo <= hi")
    return lo, hi
