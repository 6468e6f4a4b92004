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
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.signal
from numpy.typing import ArrayLike

from ehss._checks import as_record, check_band, check_fs, check_int, check_real
from ehss.errors import DataError, ParameterError

__all__ = [
    "FrequencyResponse",
    "EXCITATION_FLOOR",
    "FRF_METHODS",
    "h1_estimate",
    "dft_estimate",
    "frf_estimate",
    "default_nperseg",
    "n_segments",
]

#: Accepted ``method`` of :func:`frf_estimate`.
FRF_METHODS = ("auto", "welch", "dft")

#: Fewest samples accepted by :func:`h1_estimate`.
MIN_SAMPLES = 16

#: Fewest averages the default segment length aims for (Welch segments or DFT bins).
MIN_AVERAGES = 8
#: fewest averages a segment as long as the system's memory may leave (rule 3 of
#: default_nperseg): a validation's tolerance widens with the random error of fewer
#: averages, but nothing allows for the bias of a segment too short
MIN_AVERAGES_FOR_MEMORY = 4

#: Fraction of the record tapered (half at each end) by :func:`dft_estimate`.
TAPER_FRACTION = 0.1

#: A frequency counts as excited when the input's spectrum there is at least this fraction
#: of its largest value in the band considered (30 dB down).
EXCITATION_FLOOR = 1e-3


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
        Number of Welch segments averaged (``method="welch"``), or of adjacent DFT bins
        averaged per point (``method="dft"``).
    nperseg : int
        Segment length in samples, so the frequency resolution is ``fs / nperseg``; for
        ``method="dft"`` the equivalent length ``n_samples // n_averages``.
    fs : float
        Sample rate in Hz.
    method : {"welch", "dft"}
        How it was estimated: :func:`h1_estimate` or :func:`dft_estimate`.
    input_power : ndarray, shape (n_freq,), optional
        The input's (auto-)spectrum at each point, in any consistent scale: where the
        input put no power the estimate means nothing, whatever the coherence
        (:func:`ehss.validation.frf_error` leaves such points out).
    delay_samples : int
        Samples the output was read late by before the averages (:func:`h1_estimate`'s
        ``delay``); the response includes the lag.
    """

    freq_hz: np.ndarray = field(repr=False)
    response: np.ndarray = field(repr=False)
    coherence: np.ndarray = field(repr=False)
    n_averages: int
    nperseg: int
    fs: float
    method: str = "welch"
    input_power: np.ndarray | None = field(default=None, repr=False)
    delay_samples: int = 0

    def __post_init__(self) -> None:
        n = np.shape(self.freq_hz)
        if np.shape(self.response) != n or np.shape(self.coherence) != n or (
            self.input_power is not None and np.shape(self.input_power) != n
        ):
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
        TypeError
            If an edge is not a real number.
        ParameterError
            If ``lo_hz >= hi_hz`` or either is negative/non-finite.
        """
        lo_hz, hi_hz = check_band((lo_hz, hi_hz), "band")
        mask = (self.freq_hz >= lo_hz) & (self.freq_hz <= hi_hz)
        return FrequencyResponse(
            freq_hz=self.freq_hz[mask],
            response=self.response[mask],
            coherence=self.coherence[mask],
            n_averages=self.n_averages,
            nperseg=self.nperseg,
            fs=self.fs,
            method=self.method,
            input_power=None if self.input_power is None else self.input_power[mask],
            delay_samples=self.delay_samples,
        )

    def valid(self, band_hz: tuple[float, float], min_coherence: float) -> np.ndarray:
        """Points inside ``band_hz`` that the input excited (its spectrum within
        :data:`EXCITATION_FLOOR` of its largest value in the band) and whose coherence
        reaches ``min_coherence``: where the estimate can be trusted."""
        lo, hi = check_band(band_hz)
        ok = (self.freq_hz >= lo) & (self.freq_hz <= hi)
        if self.input_power is not None and np.any(ok):
            ok &= self.input_power >= EXCITATION_FLOOR * float(np.max(self.input_power[ok]))
        return ok & (self.coherence >= min_coherence)

    def covered_decades(self, band_hz: tuple[float, float], min_coherence: float) -> float:
        """Width in decades of the part of ``band_hz`` where the estimate is :meth:`valid`:
        each valid point at f covers ``log10((f + df/2) / (f - df/2))``, df the resolution
        (a point at f <= df/2 counts as from df/4). On a logarithmic axis, as a loop's
        response is read, so the low frequencies a sweep spends long on count fully."""
        ok = self.valid(band_hz, min_coherence)
        f = self.freq_hz[ok]
        half = 0.5 * self.resolution_hz
        return float(np.sum(np.log10((f + half) / np.maximum(f - half, 0.5 * half))))

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


def default_nperseg(
    n_samples: int,
    fs: float,
    *,
    band_hz: tuple[float, float] | None = None,
    min_averages: int = MIN_AVERAGES,
    min_nperseg: int | None = None,
) -> int:
    """Default Welch segment length, from the record's length, the band of interest and
    the memory of the system measured.

    The rule (powers of two throughout):

    1. the longest segment that still gives ``min_averages`` half-overlapping averages
       (the finest resolution the record can afford with a usable coherence);
    2. with a band ``(lo, hi)``, no longer than needed for a resolution of
       ``min(lo / 2, (hi − lo) / 32)`` (``(hi − lo) / 32`` when ``lo`` is 0): the shortest
       segment reaching it, which leaves the rest of the record for more averages;
    3. with ``min_nperseg``, at least that long, as far as the record affords
       :data:`MIN_AVERAGES_FOR_MEMORY` averages (fewer than rule 1 asks): a segment
       short against the system's impulse response biases the estimate (a dead time τ
       lowers the coherence by about (1 − τ/T)², and a resonance is smeared unless the
       resolution is finer than a quarter of its half-power bandwidth; Bendat & Piersol,
       *Random Data*, ch. 9, bias errors), whatever resolution the band asks for, and a
       comparison with the estimate allows for its random error (which fewer averages
       increase) but not for its bias;
    4. at least 16 samples when the record has them (8 otherwise).

    The sample rate enters only through the band: a record at 1 Hz and one at 4 kHz of
    the same length get the same segments unless a band says otherwise.

    Examples
    --------
    >>> default_nperseg(1000, 1.0)       # 14 averages of 128 samples
    128
    >>> default_nperseg(20_000, 1000.0)  # 8 averages, 0.24 Hz resolution
    4096
    >>> default_nperseg(20_000, 1000.0, band_hz=(2.0, 100.0))  # 1 Hz is enough
    1024
    >>> default_nperseg(20_000, 1000.0, band_hz=(2.0, 100.0), min_nperseg=1500)
    2048
    >>> default_nperseg(30_000, 1000.0, min_nperseg=6000)  # 6 averages, not 8
    8192
    """
    n = check_int(n_samples, "n_samples")
    fs = check_fs(fs)
    min_averages = check_int(min_averages, "min_averages", lo=1)
    floor = 16 if n >= 16 * (min_averages + 1) // 2 else 8
    nperseg = _longest_segment(n, min_averages, floor)
    if band_hz is not None:
        lo, hi = check_band(band_hz)
        need_hz = (hi - lo) / 32.0
        if lo > 0:
            need_hz = min(need_hz, lo / 2.0)
        if need_hz > 0:
            # shortest power of two with fs / nperseg <= need_hz
            n_need = 2 ** max(3, math.ceil(math.log2(fs / need_hz)))
            nperseg = max(min(nperseg, n_need), min(floor, nperseg))
    if min_nperseg is not None and min_nperseg > nperseg:
        longest = _longest_segment(n, min(min_averages, MIN_AVERAGES_FOR_MEMORY), floor)
        nperseg = max(nperseg, min(2 ** math.ceil(math.log2(min_nperseg)), longest))
    return nperseg


def _longest_segment(n: int, min_averages: int, floor: int) -> int:
    """The longest power-of-two segment (at least ``floor``) that gives ``min_averages``
    half-overlapping averages of ``n`` samples."""
    nperseg = 2 ** max(3, int(math.floor(math.log2(max(n, 8)))))
    while nperseg > floor and n_segments(n, nperseg, nperseg // 2) < min_averages:
        nperseg //= 2
    return nperseg


def h1_estimate(
    u: ArrayLike,
    y: ArrayLike,
    fs: float,
    *,
    nperseg: int | None = None,
    noverlap: int | None = None,
    window: str | tuple = "hann",
    detrend: str | bool = "constant",
    band_hz: tuple[float, float] | None = None,
    min_nperseg: int | None = None,
    delay: int | str = 0,
) -> FrequencyResponse:
    """H1 frequency-response estimate and coherence from input ``u`` to output ``y``.

    Parameters
    ----------
    u, y : array_like, shape (n_samples,)
        Input (e.g. the reference of a closed loop) and output, finite, same length.
    fs : float
        Sample rate in Hz.
    nperseg : int, optional
        Segment length. Default :func:`default_nperseg` (from the record's length and
        ``band_hz``): at least 8 averages, no finer resolution than the band needs.
    noverlap : int, optional
        Overlap between segments (default ``nperseg // 2``).
    window : str or tuple, default "hann"
        Window passed to :func:`scipy.signal.get_window` (the paper's Hanning window).
    detrend : {"constant", "linear", False}, default "constant"
        Detrending of each segment. When the segments are detrended the 0 Hz point carries
        no information and is left out.
    band_hz : (float, float), optional
        Band of interest, used only for the default ``nperseg``.
    min_nperseg : int, optional
        The system's memory in samples, used only for the default ``nperseg`` (see
        :func:`default_nperseg`).
    delay : int or "auto", default 0
        Samples by which the output lags the input, taken out before the averages: each
        segment of ``y`` is taken ``delay`` samples after the segment of ``u`` (the
        record one ``delay`` shorter), and the response is turned back by
        :math:`e^{-j 2\\pi f\\,delay/f_s}`. "auto": the lag, from 0 to a quarter segment,
        of the largest cross-correlation of ``u`` and ``y``. A segment of length T over
        an output that lags by τ holds only part of the response to its own input,
        which lowers the coherence by about (1 − τ/T)² and biases the estimate (Bendat &
        Piersol, *Random Data*, sec. 9.1.4); aligned, the segments see the lag as part of
        a response that they hold in full. Any delay gives the same estimate as the
        record grows: it matters for short records of a loop that lags.

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
    (4096, 8)
    """
    u, y = as_record(u, y)
    fs = check_fs(fs)
    n = u.size
    if n < MIN_SAMPLES:
        raise DataError(f"too few samples for a frequency response: {n} < {MIN_SAMPLES}")
    if nperseg is None:
        nperseg = default_nperseg(n, fs, band_hz=band_hz, min_nperseg=min_nperseg)
    else:
        nperseg = check_int(nperseg, "nperseg")
        if nperseg < 4:
            raise ParameterError(f"{nperseg=} must be >= 4")
        if nperseg > n:
            raise DataError(f"{nperseg=} is longer than the record ({n} samples)")
    if noverlap is None:
        noverlap = nperseg // 2
    else:
        noverlap = check_int(noverlap, "noverlap")
        if not 0 <= noverlap < nperseg:
            raise ParameterError(f"{noverlap=} must satisfy 0 <= noverlap < nperseg={nperseg}")
    if detrend not in ("constant", "linear", False):
        raise ParameterError(f"{detrend=} must be 'constant', 'linear' or False")
    if not np.any(u != u[0]):
        raise DataError("the input u is constant: it has no power to estimate a response")

    lag = _lag(u, y, nperseg, delay)
    if lag:
        u, y, n = u[:n - lag], y[lag:], n - lag
    weights = _check_window(window, nperseg)
    kw = dict(fs=fs, window=weights, nperseg=nperseg, noverlap=noverlap, detrend=detrend)
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
    if lag:
        # the output was read ``lag`` samples early: its response turned back
        response *= np.exp(-2j * np.pi * freq * lag / fs)
    return FrequencyResponse(
        freq_hz=freq,
        response=response,
        coherence=coherence,
        n_averages=n_segments(n, nperseg, noverlap),
        nperseg=nperseg,
        fs=fs,
        input_power=s_uu.copy(),
        delay_samples=lag,
    )


def _lag(u: np.ndarray, y: np.ndarray, nperseg: int, delay: int | str) -> int:
    """The samples ``y`` is read late by (:func:`h1_estimate`'s ``delay``), at most
    what leaves the record a full segment."""
    most = u.size - nperseg
    if isinstance(delay, str):
        if delay != "auto":
            raise ParameterError(f"{delay=} must be a number of samples or 'auto'")
        longest = min(nperseg // 4, most)
        if longest <= 0:
            return 0
        # c[k] = sum_i (u_i - ū)(y_{i+k} - ȳ), k = 0..longest
        c = scipy.signal.correlate(y - np.mean(y), u - np.mean(u), mode="full", method="fft")
        zero = u.size - 1
        return int(np.argmax(np.abs(c[zero:zero + longest + 1])))
    lag = check_int(delay, "delay", lo=0)
    if lag > most:
        raise DataError(f"{delay=} leaves less than a segment ({nperseg} samples) of "
                        f"the record ({u.size} samples)")
    return lag


def dft_estimate(
    u: ArrayLike,
    y: ArrayLike,
    fs: float,
    *,
    n_average: int | None = None,
    band_hz: tuple[float, float] | None = None,
) -> FrequencyResponse:
    """Frequency response from the DFTs of the whole record, averaged over adjacent bins.

    The estimate for a swept sine (and any test that starts and ends at rest): a sweep
    puts each frequency in the record only while it passes, so Welch segments see it in
    one segment and noise in the others, and its coherence collapses, although the
    record determines the response well. Here, as a sweep analyser does by tracking the
    sweep, every frequency is measured over the whole time it was excited.

    Parameters
    ----------
    u, y : array_like, shape (n_samples,)
        Input and output, finite, same length; their means are removed.
    fs : float
        Sample rate in Hz.
    n_average : int, optional
        Adjacent DFT bins averaged per point, L (at least 2). Default: the record length
        over :func:`default_nperseg` for ``band_hz``, at least :data:`MIN_AVERAGES`.
    band_hz : (float, float), optional
        Band of interest, used only for the default ``n_average``.

    Returns
    -------
    FrequencyResponse
        ``method="dft"``; one point per group of L bins (at the group's mean frequency,
        the 0 Hz bin left out), ``n_averages = L``.

    Notes
    -----
    With :math:`U_k, Y_k` the DFTs of the mean-removed, end-tapered record and
    :math:`\\mathcal K` a group of L adjacent bins,

    .. math:: \\hat H = \\frac{\\sum_{\\mathcal K} \\overline{U_k} Y_k}
              {\\sum_{\\mathcal K} |U_k|^2}, \\qquad
              \\hat\\gamma^2 = \\frac{|\\sum_{\\mathcal K} \\overline{U_k} Y_k|^2}
              {\\sum_{\\mathcal K} |U_k|^2 \\sum_{\\mathcal K} |Y_k|^2},

    the frequency-smoothed (Daniell) form of H1: unbiased by output noise, with L playing
    the part of the number of averages. The ends of the record are tapered over 5 % of
    its length each (Tukey window, :data:`TAPER_FRACTION`): a record cut from a longer
    test then leaks little, and a slowly varying window scales the input and the output
    alike as long as the impulse response is shorter than the taper.
    """
    u, y = as_record(u, y)
    fs = check_fs(fs)
    n = u.size
    if n < MIN_SAMPLES:
        raise DataError(f"too few samples for a frequency response: {n} < {MIN_SAMPLES}")
    if not np.any(u != u[0]):
        raise DataError("the input u is constant: it has no power to estimate a response")
    n_bins = n // 2  # bins 1 .. n//2
    if n_average is None:
        n_average = max(MIN_AVERAGES, n // default_nperseg(n, fs, band_hz=band_hz))
    else:
        n_average = check_int(n_average, "n_average")
        if n_average < 2:
            raise ParameterError(f"{n_average=} must be >= 2")
    n_average = min(n_average, n_bins)
    n_groups = n_bins // n_average
    if n_groups < 1:
        raise DataError(f"{n} samples hold fewer than {n_average} frequency bins")
    # A short cosine taper (5 % of the record at each end) keeps a record that does not
    # start or end at rest (the held-out end of a sweep) from leaking its cut into
    # frequencies it never excited; a slow taper scales U and Y alike, not their ratio.
    taper = scipy.signal.windows.tukey(n, TAPER_FRACTION)
    uf = np.fft.rfft((u - u.mean()) * taper)
    yf = np.fft.rfft((y - y.mean()) * taper)
    f = np.fft.rfftfreq(n, 1.0 / fs)
    sl = slice(1, 1 + n_groups * n_average)
    shape = (n_groups, n_average)
    # S_uy = Σ conj(U) Y, S_uu = Σ |U|², S_yy = Σ |Y|² over each group of L bins
    s_uy = (np.conj(uf[sl]) * yf[sl]).reshape(shape).sum(axis=1)
    s_uu = (np.abs(uf[sl]) ** 2).reshape(shape).sum(axis=1)
    s_yy = (np.abs(yf[sl]) ** 2).reshape(shape).sum(axis=1)
    freq = f[sl].reshape(shape).mean(axis=1)
    response = np.zeros(n_groups, dtype=np.complex128)
    coherence = np.zeros(n_groups, dtype=np.float64)
    ok = s_uu > 0
    # H = S_uy / S_uu
    response[ok] = s_uy[ok] / s_uu[ok]
    ok_y = ok & (s_yy > 0)
    # γ² = |S_uy|² / (S_uu S_yy)
    coherence[ok_y] = np.abs(s_uy[ok_y]) ** 2 / (s_uu[ok_y] * s_yy[ok_y])
    np.clip(coherence, 0.0, 1.0, out=coherence)
    return FrequencyResponse(freq_hz=freq, response=response, coherence=coherence,
                             n_averages=n_average, nperseg=n // n_average, fs=fs,
                             method="dft", input_power=s_uu)


def frf_estimate(
    u: ArrayLike,
    y: ArrayLike,
    fs: float,
    *,
    method: str = "auto",
    nperseg: int | None = None,
    band_hz: tuple[float, float] | None = None,
    min_coherence: float = 0.9,
    min_nperseg: int | None = None,
) -> FrequencyResponse:
    """Non-parametric frequency response by Welch averaging, whole-record DFTs, or
    whichever of the two the record supports better.

    Parameters
    ----------
    u, y : array_like, shape (n_samples,)
    fs : float
        Sample rate in Hz.
    method : {"auto", "welch", "dft"}, default "auto"
        ``"welch"``: :func:`h1_estimate`; ``"dft"``: :func:`dft_estimate`; ``"auto"``:
        both, keeping the DFT estimate only when it is valid (coherent and excited) over a
        quarter more of ``band_hz`` (of the whole axis without a band) than Welch's,
        measured in decades (:meth:`FrequencyResponse.covered_decades`): random and
        multisine tests keep Welch's estimate, fast sweeps get the DFT estimate.
    nperseg : int, optional
        Welch segment length (and, as ``n_samples // nperseg``, the DFT estimate's number
        of averaged bins). Default: :func:`default_nperseg`.
    band_hz : (float, float), optional
        Band of interest (defaults and the ``"auto"`` choice).
    min_coherence : float, default 0.9
        Coherence counted as good by ``"auto"``.
    min_nperseg : int, optional
        The system's memory in samples, for the default Welch segment
        (:func:`default_nperseg`); the DFT estimate needs none (whole periods).

    Returns
    -------
    FrequencyResponse
        Its ``method`` says which estimate it is.
    """
    if method not in FRF_METHODS:
        raise ParameterError(f"method={method!r} must be one of {', '.join(FRF_METHODS)}")
    min_coherence = check_real(min_coherence, "min_coherence", lo=0.0, hi=1.0)
    if method == "welch":
        return h1_estimate(u, y, fs, nperseg=nperseg, band_hz=band_hz,
                           min_nperseg=min_nperseg)
    n_average = None
    if nperseg is not None:
        n_u = np.shape(u)[0] if np.ndim(u) == 1 else 0
        n_average = max(2, n_u // check_int(nperseg, "nperseg")) if n_u else None
    dft = dft_estimate(u, y, fs, n_average=n_average, band_hz=band_hz)
    if method == "dft":
        return dft
    welch = h1_estimate(u, y, fs, nperseg=nperseg, band_hz=band_hz, min_nperseg=min_nperseg)
    band = band_hz if band_hz is not None else (0.0, welch.fs / 2.0)
    # the DFT estimate only when it validates over clearly more of the band (a quarter
    # more): on stationary tests both cover the same and Welch's estimate is kept
    if dft.covered_decades(band, min_coherence) > 1.25 * welch.covered_decades(
            band, min_coherence):
        return dft
    return welch


# ------------------------------------------------------------------------------- checks


def _check_window(window: Any, nperseg: int) -> np.ndarray:
    """The window's nperseg samples: a name or (name, parameter) tuple that
    :func:`scipy.signal.get_window` knows; anything else is a ParameterError."""
    if isinstance(window, np.ndarray) or not isinstance(window, (str, tuple)):
        raise ParameterError(f"window={window!r} must be a window name such as 'hann', or a "
                             "(name, parameter) tuple such as ('tukey', 0.25)")
    try:
        w = scipy.signal.get_window(window, nperseg)
    except (ValueError, TypeError) as exc:
        raise ParameterError(f"window={window!r} is not a window scipy knows: {exc}") from None
    if not np.all(np.isfinite(w)) or not np.any(w > 0):
        raise ParameterError(f"window={window!r} gives no positive finite weights")
    return w
