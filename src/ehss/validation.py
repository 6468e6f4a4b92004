"""Validation of identified models: fit figures, frequency-response error, residual tests.

The paper judges each identified closed loop by eye against the measured time response and
the Hanning-window frequency response (Figs 13–15). This module puts numbers on the same
comparisons:

- :func:`frf_error`: magnitude (dB) and phase (deg) error of the model against an H1
  estimate (:mod:`ehss.frequency`) over a band, where the coherence is high enough;
- :func:`nrmse_fit`, :func:`simulation_fit`, :func:`prediction_fit`: the "fit" percentage
  of MATLAB's System Identification Toolbox (``compare``), for the free-run simulation
  (from a zero or a least-squares initial state, :func:`free_run`) and k-step prediction;
  :func:`band_fit` scores the simulation over the band of interest only;
- :func:`residual_tests`: whiteness of the one-step residuals (per-lag bounds and the
  Ljung–Box portmanteau test) and their independence from the input;
- :func:`validate`: all of the above on held-out data or a separate record, bundled in a
  :class:`ValidationReport`.

A fit below :data:`DIVERGED_FIT_PCT` (−100 %: the simulation is more than twice as far
from the data as the data's mean) is reported as a diverging simulation, not as a number.

The model is any object with the :class:`~ehss.identification.model.ArmaxModel` methods
``frequency_response(freq_hz)``, ``simulate(u)``, ``predict(u, y, horizon)``,
``is_stable()`` and ``poles()``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
import scipy.signal
import scipy.stats
from numpy.typing import ArrayLike

from ehss._checks import as_record, as_signal, check_band, check_int, check_real
from ehss.errors import DataError, ParameterError
from ehss.frequency import FrequencyResponse, frf_estimate

__all__ = [
    "FrfError",
    "ResidualTests",
    "ValidationReport",
    "frf_error",
    "nrmse_fit",
    "free_run",
    "simulation_fit",
    "band_fit",
    "fit_text",
    "DIVERGED_FIT_PCT",
    "INITIAL_STATES",
    "prediction_fit",
    "residual_tests",
    "segment_floor",
    "ljung_box",
    "validate",
]


#: Fits below this (percent) are reported as a diverging simulation.
DIVERGED_FIT_PCT = -100.0

#: How :func:`free_run` starts the simulation: from rest, or from the initial state that
#: fits the data best (MATLAB ``compare``'s ``InitialCondition`` ``'z'`` and ``'e'``).
INITIAL_STATES = ("zero", "estimate")


class _Model(Protocol):  # the part of ArmaxModel used here
    def frequency_response(self, freq_hz: np.ndarray) -> np.ndarray: ...
    def simulate(self, u: np.ndarray) -> np.ndarray: ...
    def predict(self, u: np.ndarray, y: np.ndarray, horizon: int = 1) -> np.ndarray: ...
    def is_stable(self) -> bool: ...
    def poles(self) -> np.ndarray: ...

    @property
    def a(self) -> np.ndarray: ...
    @property
    def b(self) -> np.ndarray: ...
    @property
    def delay(self) -> int: ...


# ------------------------------------------------------------------------------ FRF error


@dataclass(frozen=True, kw_only=True, eq=False)
class FrfError:
    """Error of a model's frequency response against an H1 estimate.

    Attributes
    ----------
    band_hz : tuple of float
        The band ``(lo, hi)`` compared, Hz.
    min_coherence : float
        Points with a lower coherence were left out.
    n_points : int
        Number of frequency points used (0: nothing to compare, all errors NaN).
    compared_hz : tuple of float
        Lowest and highest frequency among those points, Hz (NaN when there are none):
        where the comparison really took place inside ``band_hz``.
    max_magnitude_db, rms_magnitude_db : float
        Largest and RMS of ``|20 log10 |G| - 20 log10 |H1||`` in dB.
    weighted_rms_magnitude_db : float
        RMS magnitude error weighted by the coherence.
    max_phase_deg, rms_phase_deg : float
        Largest and RMS absolute phase error in degrees, each wrapped to ±180°.
    freq_hz, magnitude_error_db, phase_error_deg : ndarray, shape (n_points,)
        The compared frequencies and the signed errors there.
    sigma_magnitude_db, sigma_phase_deg : ndarray, shape (n_points,)
        Standard error of the estimate itself at each point, from its coherence and
        number of averages (see :func:`frf_error`): how well it can confirm a model.
    """

    band_hz: tuple[float, float]
    min_coherence: float
    n_points: int
    compared_hz: tuple[float, float]
    max_magnitude_db: float
    rms_magnitude_db: float
    weighted_rms_magnitude_db: float
    max_phase_deg: float
    rms_phase_deg: float
    freq_hz: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)
    magnitude_error_db: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)
    phase_error_deg: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)
    sigma_magnitude_db: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)
    sigma_phase_deg: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)

    def excess(self, n_sigma: float) -> tuple[np.ndarray, np.ndarray]:
        """Each point's absolute magnitude (dB) and phase (deg) errors less ``n_sigma``
        standard errors of the estimate there (negative: within them)."""
        return (np.abs(self.magnitude_error_db) - n_sigma * self.sigma_magnitude_db,
                np.abs(self.phase_error_deg) - n_sigma * self.sigma_phase_deg)

    def beyond_uncertainty(self, n_sigma: float, points: np.ndarray | None = None
                           ) -> tuple[float, float]:
        """Largest magnitude (dB) and phase (deg) errors left after subtracting
        ``n_sigma`` standard errors of the estimate at each point (0 where the error is
        within them; NaN when nothing was compared), over ``points`` (a mask of
        :attr:`freq_hz`; default all)."""
        mag, ph = self.excess(n_sigma)
        if points is not None:
            mag, ph = mag[points], ph[points]
        if mag.size == 0:
            return math.nan, math.nan
        return float(max(0.0, np.max(mag))), float(max(0.0, np.max(ph)))

    def worst_beyond_uncertainty(self, n_sigma: float, magnitude_db: float,
                                 phase_deg: float) -> float:
        """Frequency (Hz) of the point whose error, less ``n_sigma`` standard errors of
        the estimate, is largest against its bound (``magnitude_db`` in magnitude,
        ``phase_deg`` in phase, whichever is the larger share): where a model is
        furthest beyond what the estimate confirms (NaN when nothing was compared)."""
        if self.n_points == 0:
            return math.nan
        mag, ph = self.excess(n_sigma)
        return float(self.freq_hz[int(np.argmax(np.maximum(mag / magnitude_db,
                                                            ph / phase_deg)))])

    def summary(self) -> dict[str, Any]:
        """Plain floats/ints for JSON."""
        return {
            "band_hz": [float(self.band_hz[0]), float(self.band_hz[1])],
            "min_coherence": float(self.min_coherence),
            "n_points": int(self.n_points),
            "compared_hz": [float(self.compared_hz[0]), float(self.compared_hz[1])],
            "max_magnitude_db": float(self.max_magnitude_db),
            "rms_magnitude_db": float(self.rms_magnitude_db),
            "weighted_rms_magnitude_db": float(self.weighted_rms_magnitude_db),
            "max_phase_deg": float(self.max_phase_deg),
            "rms_phase_deg": float(self.rms_phase_deg),
        }


def frf_error(
    model: _Model,
    frf: FrequencyResponse,
    *,
    band_hz: tuple[float, float],
    min_coherence: float = 0.9,
) -> FrfError:
    """Magnitude and phase error of ``model`` against the estimate ``frf`` over a band.

    Parameters
    ----------
    model : ArmaxModel
        Anything with ``frequency_response(freq_hz) -> complex ndarray``.
    frf : FrequencyResponse
        The non-parametric estimate (:func:`ehss.frequency.h1_estimate`).
    band_hz : (float, float)
        Frequencies ``lo <= f <= hi`` (Hz) to compare.
    min_coherence : float, default 0.9
        Points whose coherence is below this are unreliable and left out, and so are
        points the input did not excite (:meth:`FrequencyResponse.valid`).

    Returns
    -------
    FrfError
        With ``n_points == 0`` and NaN errors when no point qualifies.

    Notes
    -----
    With :math:`G` the model and :math:`H` the estimate, per frequency

    .. math:: e_{dB} = 20\\log_{10}|G| - 20\\log_{10}|H|, \\qquad
              e_{\\varphi} = \\arg(G\\,\\overline{H}) \\in (-180°, 180°],

    so the phase error needs no unwrapping. The weighted RMS uses :math:`\\gamma^2` as the
    weight of each point. Each point also carries the estimate's own standard error,
    :math:`\\varepsilon = \\sqrt{1-\\gamma^2} / (|\\gamma|\\sqrt{2 n_d})` relative for
    :math:`|H|` and in radians for its phase, with :math:`n_d` the averages (Bendat &
    Piersol, *Random Data*, eqs 9.90 and 9.92): at :math:`\\gamma^2 = 0.9` and 8
    averages it is already 0.7 dB and 4.8°.
    """
    lo, hi = check_band(band_hz)
    min_coherence = check_real(min_coherence, "min_coherence", lo=0.0, hi=1.0)
    # in the band, excited by the input and coherent (FrequencyResponse.valid)
    mask = frf.valid((lo, hi), float(min_coherence))
    mask &= np.abs(frf.response) > 0
    n = int(mask.sum())
    if n == 0:
        nan = float("nan")
        return FrfError(band_hz=(lo, hi), min_coherence=float(min_coherence), n_points=0,
                        compared_hz=(nan, nan), max_magnitude_db=nan, rms_magnitude_db=nan,
                        weighted_rms_magnitude_db=nan, max_phase_deg=nan, rms_phase_deg=nan)
    f = frf.freq_hz[mask]
    h = frf.response[mask]
    w = frf.coherence[mask]
    g = np.asarray(model.frequency_response(f), dtype=np.complex128)
    if g.shape != f.shape:
        raise ParameterError(f"model.frequency_response returned shape {g.shape}, "
                             f"expected {f.shape}")
    with np.errstate(divide="ignore"):
        # e_dB = 20 log10 |G| - 20 log10 |H|
        e_db = 20.0 * np.log10(np.abs(g)) - 20.0 * np.log10(np.abs(h))
    # e_phi = arg(G conj(H)), wrapped to (-180, 180] by construction
    e_ph = np.degrees(np.angle(g * np.conj(h)))
    # standard error of the estimate: eps = sqrt(1 - g2) / (|g| sqrt(2 n_d)) for |H| and,
    # in radians, for its phase (Bendat & Piersol, eqs 9.90 and 9.92)
    n_d = max(int(frf.n_averages), 1)
    eps = np.sqrt(np.maximum(1.0 - w, 0.0) / (np.maximum(w, 1e-12) * 2.0 * n_d))
    sig_db = 20.0 / math.log(10.0) * eps
    sig_deg = np.degrees(eps)
    return FrfError(
        band_hz=(lo, hi),
        min_coherence=float(min_coherence),
        n_points=n,
        compared_hz=(float(np.min(f)), float(np.max(f))),
        max_magnitude_db=float(np.max(np.abs(e_db))),
        rms_magnitude_db=float(np.sqrt(np.mean(e_db**2))),
        weighted_rms_magnitude_db=float(np.sqrt(np.sum(w * e_db**2) / np.sum(w))),
        max_phase_deg=float(np.max(np.abs(e_ph))),
        rms_phase_deg=float(np.sqrt(np.mean(e_ph**2))),
        freq_hz=f,
        magnitude_error_db=e_db,
        phase_error_deg=e_ph,
        sigma_magnitude_db=sig_db,
        sigma_phase_deg=sig_deg,
    )


# ----------------------------------------------------------------------------- fit figures


def nrmse_fit(y: ArrayLike, yhat: ArrayLike) -> float:
    """Normalised fit in percent, as MATLAB's ``compare``/``goodnessOfFit('NRMSE')``.

    .. math:: \\mathrm{fit} = 100\\left(1 - \\frac{\\lVert y - \\hat y\\rVert}
              {\\lVert y - \\bar y\\rVert}\\right)

    100 is a perfect match, 0 is no better than the mean of ``y``, and it is negative (and
    unbounded) for worse predictions. A diverging ``yhat`` gives ``-inf``.

    Raises
    ------
    DataError
        If the shapes differ, ``y`` is constant or ``y`` is non-finite.
    """
    y = np.asarray(y, dtype=np.float64)
    yhat = np.asarray(yhat, dtype=np.float64)
    if y.shape != yhat.shape or y.ndim != 1:
        raise DataError(f"y and yhat must be 1-D of the same length, got {y.shape} "
                        f"and {yhat.shape}")
    if y.size == 0 or not np.all(np.isfinite(y)):
        raise DataError("y must be non-empty and finite")
    if not np.all(np.isfinite(yhat)):
        return -math.inf
    den = np.linalg.norm(y - np.mean(y))
    if den == 0.0:
        raise DataError("y is constant: the fit is undefined")
    with np.errstate(over="ignore"):
        num = np.linalg.norm(y - yhat)
    return float(100.0 * (1.0 - num / den)) if math.isfinite(num) else -math.inf


def free_run(model: _Model, u: ArrayLike, y: ArrayLike | None = None, *,
             initial: str = "zero") -> np.ndarray:
    """Free-run simulation ``B/A u`` of the model, from rest or from a fitted initial state.

    Parameters
    ----------
    model : ArmaxModel
    u : array_like, shape (n_samples,)
    y : array_like, shape (n_samples,), optional
        Measured output; needed for ``initial="estimate"``.
    initial : {"zero", "estimate"}, default "zero"
        ``"estimate"``: add the free response of the model that best fits ``y`` in least
        squares (as MATLAB ``compare`` does by default). An unstable model is simulated
        from rest: a growing free response fitted to data would hide its divergence.

    Returns
    -------
    ndarray, shape (n_samples,)

    Notes
    -----
    With :math:`m = \\max(n_a, n_b + d)` past values, every free response of the model
    is a combination of the responses :math:`h(k - j)` of :math:`1/A` to unit impulses at
    :math:`j = 0 .. m-1`; the weights solve
    :math:`\\min_x \\lVert y - y_0 - \\Phi x\\rVert` with :math:`y_0` the response
    from rest. The free response of a stable model dies out, so in effect the first
    samples decide it.
    """
    if initial not in INITIAL_STATES:
        raise ParameterError(f"initial={initial!r} must be one of {INITIAL_STATES}")
    u = as_signal(u, "u")
    with np.errstate(over="ignore", invalid="ignore"):
        y0 = np.asarray(model.simulate(u), dtype=np.float64)
    if initial == "zero":
        return y0
    if y is None:
        raise ParameterError("initial='estimate' needs the measured output y")
    _, y = as_record(u, y)
    if not model.is_stable() or not np.all(np.isfinite(y0)):
        return y0
    n = u.size
    a = np.asarray(model.a, dtype=np.float64)
    m = min(n, max(a.size - 1, np.asarray(model.b).size - 1 + int(model.delay), 1))
    impulse = np.zeros(n)
    impulse[0] = 1.0
    h = scipy.signal.lfilter([1.0], a, impulse)
    phi = np.zeros((n, m))
    for j in range(m):  # Φ[:, j] = h(k − j)
        phi[j:, j] = h[: n - j]
    x, *_ = np.linalg.lstsq(phi, y - y0, rcond=None)
    return y0 + phi @ x


def simulation_fit(model: _Model, u: ArrayLike, y: ArrayLike, *, start: int = 0,
                   initial: str = "zero") -> float:
    """Fit (percent, :func:`nrmse_fit`) of the noise-free simulation ``B/A u`` to ``y``.

    The model is simulated over the whole record (:func:`free_run`, from rest or from the
    least-squares initial state) and scored from sample ``start`` on, so a held-out part
    starts from the state the earlier part left. An unstable model's simulation diverges
    and scores ``-inf`` or far below :data:`DIVERGED_FIT_PCT`.
    """
    u, y = as_record(u, y)
    start = check_int(start, "start", lo=0, hi=y.size - 1)
    yhat = free_run(model, u, y, initial=initial)
    return nrmse_fit(y[start:], yhat[start:])


def band_fit(y: ArrayLike, yhat: ArrayLike, *, fs: float, band_hz: tuple[float, float]) -> float:
    """Fit (percent) of ``yhat`` to ``y`` with both low-passed to the band of interest.

    Both go through the same zero-phase 4th-order Butterworth low-pass at
    ``min(1.5 hi, 0.45 fs)``: output noise above the band (sensor noise, which the model
    is not meant to reproduce) no longer counts against the model. Returns the plain
    :func:`nrmse_fit` when the band reaches that close to Nyquist already.
    """
    y = as_signal(y, "y")
    lo, hi = check_band(band_hz)
    cut = min(1.5 * hi, 0.45 * float(fs))
    yhat = np.asarray(yhat, dtype=np.float64)
    if cut >= 0.45 * float(fs) or not np.all(np.isfinite(yhat)) or y.size < 30:
        return nrmse_fit(y, yhat)
    sos = scipy.signal.butter(4, cut, fs=float(fs), output="sos")
    with np.errstate(over="ignore", invalid="ignore"):
        yf = scipy.signal.sosfiltfilt(sos, yhat)
    return nrmse_fit(scipy.signal.sosfiltfilt(sos, y), yf)


def fit_text(v: float | None) -> str:
    """A fit for people: ``"93.21 %"``, or ``"diverges"`` below :data:`DIVERGED_FIT_PCT`."""
    if v is None:
        return "-"
    if not math.isfinite(v) or v < DIVERGED_FIT_PCT:
        return f"diverges (fit below {DIVERGED_FIT_PCT:g} %)"
    return f"{v:.2f} %"


def prediction_fit(model: _Model, u: ArrayLike, y: ArrayLike, horizon: int = 1, *,
                   start: int = 0) -> float:
    """Fit (percent) of the ``horizon``-step-ahead ARMAX prediction of ``y``."""
    u, y = as_record(u, y)
    start = check_int(start, "start", lo=0, hi=y.size - 1)
    horizon = check_int(horizon, "horizon", lo=1)
    with np.errstate(over="ignore", invalid="ignore"):
        yhat = np.asarray(model.predict(u, y, horizon=horizon), dtype=np.float64)
    return nrmse_fit(y[start:], yhat[start:])


# --------------------------------------------------------------------------- residual tests


@dataclass(frozen=True, kw_only=True, eq=False)
class ResidualTests:
    """Whiteness and input-independence tests of one-step prediction residuals.

    Attributes
    ----------
    n_samples : int
        Residuals used.
    alpha : float
        Significance level of the tests.
    lags : ndarray of int, shape (max_lag + 1,)
        ``0 .. max_lag`` for :attr:`autocorrelation`.
    autocorrelation : ndarray, shape (max_lag + 1,)
        Normalised residual autocorrelation :math:`\\hat\\rho_e(\\tau)` (1 at lag 0).
    autocorrelation_bound : float
        Per-lag bound :math:`z_{1-\\alpha/2}/\\sqrt N` under whiteness.
    ljung_box_q, ljung_box_p : float
        Ljung–Box statistic over lags 1..max_lag and its p-value (:math:`\\chi^2_{m}`).
    white : bool
        Whiteness accepted: ``ljung_box_p >= alpha``.
    cross_lags : ndarray of int, shape (2 max_lag + 1,)
        ``-max_lag .. max_lag`` for :attr:`cross_correlation`.
    cross_correlation : ndarray, shape (2 max_lag + 1,)
        Normalised :math:`\\hat\\rho_{eu}(\\tau) = \\sum_k e(k) u(k-\\tau) / (N \\sigma_e
        \\sigma_u)`; positive lags are past inputs.
    cross_bound : float
        Bound on :math:`|\\hat\\rho_{eu}|` (Bonferroni over the lags, see
        :func:`residual_tests`).
    independent : bool
        Independence accepted: every :math:`|\\hat\\rho_{eu}(\\tau)| \\le` ``cross_bound``.
    residuals : ndarray, shape (n_samples,)
        The residuals themselves.
    """

    n_samples: int
    alpha: float
    lags: np.ndarray = field(repr=False)
    autocorrelation: np.ndarray = field(repr=False)
    autocorrelation_bound: float
    ljung_box_q: float
    ljung_box_p: float
    white: bool
    cross_lags: np.ndarray = field(repr=False)
    cross_correlation: np.ndarray = field(repr=False)
    cross_bound: float
    independent: bool
    residuals: np.ndarray = field(repr=False)

    @property
    def passed(self) -> bool:
        """Both tests accepted."""
        return bool(self.white and self.independent)

    @property
    def n_lags_outside(self) -> int:
        """Lags 1..max_lag whose autocorrelation is outside the per-lag bound."""
        return int(np.sum(np.abs(self.autocorrelation[1:]) > self.autocorrelation_bound))

    def summary(self) -> dict[str, Any]:
        """Plain values for JSON."""
        return {
            "n_samples": int(self.n_samples),
            "alpha": float(self.alpha),
            "max_lag": int(self.lags[-1]),
            "ljung_box_q": float(self.ljung_box_q),
            "ljung_box_p": float(self.ljung_box_p),
            "white": bool(self.white),
            "autocorrelation_lags_outside": self.n_lags_outside,
            "max_abs_cross_correlation": float(np.max(np.abs(self.cross_correlation))),
            "cross_bound": float(self.cross_bound),
            "independent": bool(self.independent),
        }


def ljung_box(x: ArrayLike, max_lag: int) -> tuple[float, float]:
    """Ljung–Box statistic and p-value of ``x`` over lags ``1..max_lag``.

    .. math:: Q = N(N+2)\\sum_{k=1}^{m} \\frac{\\hat\\rho_k^2}{N-k}, \\qquad
              p = P(\\chi^2_m > Q),

    with :math:`\\hat\\rho_k = \\sum_{t=k}^{N-1} x'_t x'_{t-k} / \\sum_t x'^2_t`,
    :math:`x' = x - \\bar x`.
    """
    x = np.asarray(x, dtype=np.float64)
    max_lag = check_int(max_lag, "max_lag", lo=1)
    n = x.size
    if n <= max_lag + 1:
        raise DataError(f"{n} samples are too few for {max_lag} lags")
    rho = _autocorr(x - x.mean(), max_lag)
    k = np.arange(1, max_lag + 1)
    q = float(n * (n + 2) * np.sum(rho[1:] ** 2 / (n - k)))
    return q, float(scipy.stats.chi2.sf(q, max_lag))


def residual_tests(
    model: _Model,
    u: ArrayLike,
    y: ArrayLike,
    *,
    max_lag: int = 25,
    alpha: float = 0.01,
    start: int = 0,
) -> ResidualTests:
    """Whiteness and input-independence tests of the one-step prediction residuals.

    Parameters
    ----------
    model : ArmaxModel
        Anything with ``predict(u, y, horizon=1)``.
    u, y : array_like, shape (n_samples,)
        Input and measured output.
    max_lag : int, default 25
        Largest lag tested.
    alpha : float, default 0.01
        Significance level.
    start : int, default 0
        Residuals before this sample (e.g. the estimation part) are not tested; the
        prediction still runs over the whole record so its state is warm.

    Returns
    -------
    ResidualTests

    Notes
    -----
    The residuals are :math:`e(k) = y(k) - \\hat y(k|k-1)`. Whiteness is accepted when the
    Ljung–Box p-value is at least ``alpha``; the per-lag autocorrelations and their bound
    :math:`\\pm z_{1-\\alpha/2}/\\sqrt N` are returned for plotting. For independence, if
    :math:`e` is white and independent of :math:`u`,
    :math:`\\operatorname{var}\\hat\\rho_{eu}(\\tau) = \\frac1N\\sum_k \\rho_e(k)\\rho_u(k)`
    (Ljung, *System Identification*, 2nd ed., §16.6); the sum is estimated over
    :math:`|k| \\le` ``max_lag`` (this widens the bound when the residuals are coloured,
    as MATLAB's ``resid`` does) and a Bonferroni correction over the
    :math:`2\\,\\text{max\\_lag}+1` lags keeps the test at level ``alpha``.
    """
    u, y = as_record(u, y)
    max_lag = check_int(max_lag, "max_lag", lo=1)
    alpha = check_real(alpha, "alpha", lo=0.0, hi=1.0, lo_open=True, hi_open=True)
    start = check_int(start, "start", lo=0, hi=y.size - 1)
    with np.errstate(over="ignore", invalid="ignore"):
        yhat = np.asarray(model.predict(u, y, horizon=1), dtype=np.float64)
    e = y[start:] - yhat[start:]
    uu = u[start:]
    n = e.size
    if n < max(2 * max_lag + 2, 10):
        raise DataError(f"{n} residuals are too few for residual tests up to lag {max_lag}")
    if not np.all(np.isfinite(e)):
        raise DataError("the one-step predictions are not finite (is the C polynomial stable?)")
    e0 = e - e.mean()
    u0 = uu - uu.mean()
    if not np.any(e0) or not np.any(u0):
        raise DataError("the residuals or the input are constant: nothing to test")

    rho_e = _autocorr(e0, max_lag)
    z = float(scipy.stats.norm.ppf(1.0 - alpha / 2.0))
    bound = z / math.sqrt(n)
    q, p = ljung_box(e, max_lag)

    # ρ_eu(τ) = Σ_k e(k) u(k−τ) / (N σ_e σ_u), τ = −max_lag..max_lag
    full = scipy.signal.correlate(e0, u0, mode="full", method="fft")
    mid = n - 1  # index of τ = 0 in the full correlation
    cross = full[mid - max_lag : mid + max_lag + 1] / math.sqrt(np.dot(e0, e0) * np.dot(u0, u0))
    rho_u = _autocorr(u0, max_lag)
    # var ρ_eu ≈ (1/N) Σ_{|k|≤m} ρ_e(k) ρ_u(k); never below the white-residual value 1/N
    p_sum = max(1.0, float(rho_e[0] * rho_u[0] + 2.0 * np.dot(rho_e[1:], rho_u[1:])))
    n_tests = 2 * max_lag + 1
    z_bonf = float(scipy.stats.norm.ppf(1.0 - alpha / (2.0 * n_tests)))
    cross_bound = z_bonf * math.sqrt(p_sum / n)
    return ResidualTests(
        n_samples=n,
        alpha=float(alpha),
        lags=np.arange(max_lag + 1),
        autocorrelation=rho_e,
        autocorrelation_bound=bound,
        ljung_box_q=q,
        ljung_box_p=p,
        white=bool(p >= alpha),
        cross_lags=np.arange(-max_lag, max_lag + 1),
        cross_correlation=cross,
        cross_bound=cross_bound,
        independent=bool(np.all(np.abs(cross) <= cross_bound)),
        residuals=e,
    )


# ------------------------------------------------------------------------------- validate


@dataclass(frozen=True, kw_only=True, eq=False)
class ValidationReport:
    """Everything :func:`validate` measured about one model on one record.

    Attributes
    ----------
    n_estimation, n_validation : int
        Samples before / in the held-out part (``n_estimation`` is 0 for a separate
        validation record).
    fs : float
        Sample rate, Hz.
    stable : bool
        All poles strictly inside the unit circle.
    max_pole_radius : float
        Largest pole modulus.
    initial_state : {"zero", "estimate", "warm"}
        How the simulation started: from rest, from the least-squares initial state
        (:func:`free_run`), or from rest at the start of the whole record with the
        held-out part scored (``"warm"``).
    simulation_fit_pct : float
        :func:`nrmse_fit` of the simulation on the validation part (``-inf`` if it
        diverges to overflow).
    band_fit_pct : float or None
        The same after the zero-phase low-pass of :func:`band_fit` at 1.5 times the band's
        upper edge (None without a band, or when that is above 0.45 fs).
    prediction_fit_pct : dict of int to float
        :func:`prediction_fit` on the validation part, by horizon.
    frf : FrequencyResponse
        Non-parametric estimate from the validation part (:func:`ehss.frequency.frf_estimate`).
    frf_error : FrfError or None
        Model against ``frf`` (None when no band was given).
    residuals : ResidualTests
        Tests of the one-step residuals on the validation part.
    simulated : ndarray, shape (n_samples,)
        The model's simulated output over the record given (for plots).
    operating_point_fit_pct : float or None
        For a separate validation record (:func:`ehss.workflow.assess`): the simulation
        fit with the record taken about the estimation data's operating point instead of
        its own mean. A record that drifted from the operating point fits worse so; the
        two differ by what the model does not know about the drift. None otherwise.
    """

    n_estimation: int
    n_validation: int
    fs: float
    stable: bool
    max_pole_radius: float
    initial_state: str = "zero"
    simulation_fit_pct: float
    band_fit_pct: float | None = None
    prediction_fit_pct: dict[int, float]
    frf: FrequencyResponse = field(repr=False)
    frf_error: FrfError | None
    residuals: ResidualTests = field(repr=False)
    simulated: np.ndarray = field(repr=False)
    operating_point_fit_pct: float | None = None

    @property
    def diverged(self) -> bool:
        """The free-run simulation diverges (fit below :data:`DIVERGED_FIT_PCT`)."""
        v = self.simulation_fit_pct
        return not math.isfinite(v) or v < DIVERGED_FIT_PCT

    @property
    def fit_pct(self) -> float:
        """The fit that judges the model: :attr:`band_fit_pct` if there is one, else
        :attr:`simulation_fit_pct`."""
        return self.simulation_fit_pct if self.band_fit_pct is None else self.band_fit_pct

    def summary(self) -> dict[str, Any]:
        """Plain floats, ints and bools for JSON; a diverging fit is None with
        ``"diverged": true``."""

        def fit(v: float | None) -> float | None:
            return None if v is None or not math.isfinite(v) or v < DIVERGED_FIT_PCT \
                else float(v)

        return {
            "n_estimation": int(self.n_estimation),
            "n_validation": int(self.n_validation),
            "fs_hz": float(self.fs),
            "stable": bool(self.stable),
            "max_pole_radius": float(self.max_pole_radius),
            "initial_state": self.initial_state,
            "diverged": self.diverged,
            "simulation_fit_pct": fit(self.simulation_fit_pct),
            "band_fit_pct": fit(self.band_fit_pct),
            "operating_point_fit_pct": fit(self.operating_point_fit_pct),
            "prediction_fit_pct": {str(k): fit(v) for k, v in
                                   self.prediction_fit_pct.items()},
            "frf_error": None if self.frf_error is None else self.frf_error.summary(),
            "frf": {"method": self.frf.method, "nperseg": int(self.frf.nperseg),
                    "n_averages": int(self.frf.n_averages),
                    "resolution_hz": float(self.frf.resolution_hz)},
            "residuals": self.residuals.summary(),
        }

    def format(self) -> str:
        """A few lines for the terminal."""
        r = self.residuals
        start = {"zero": "from rest", "estimate": "from the least-squares initial state",
                 "warm": "from rest at the record's start"}[self.initial_state]
        where = (f"{self.n_validation} held-out samples ({self.n_validation / self.fs:.3g} s; "
                 f"estimation used {self.n_estimation})" if self.n_estimation else
                 f"a separate record of {self.n_validation} samples "
                 f"({self.n_validation / self.fs:.3g} s)")
        lines = [
            f"validation on {where}",
            f"  stable: {'yes' if self.stable else 'NO'} "
            f"(max pole radius {self.max_pole_radius:.6f})",
            f"  simulation fit ({start}): {fit_text(self.simulation_fit_pct)}"
            + ("" if self.operating_point_fit_pct is None else
               " with the record about its own mean; "
               f"{fit_text(self.operating_point_fit_pct)} about the estimation data's "
               "operating point"),
        ]
        if self.band_fit_pct is not None and self.frf_error is not None:
            lo, hi = self.frf_error.band_hz
            lines.append(f"  simulation fit in the band (both low-passed at {1.5 * hi:g} Hz): "
                         f"{fit_text(self.band_fit_pct)}")
        for k, v in self.prediction_fit_pct.items():
            lines.append(f"  {k}-step prediction fit: {fit_text(v)}")
        e = self.frf_error
        how = (f"{self.frf.method} estimate, resolution {self.frf.resolution_hz:.3g} Hz, "
               f"{self.frf.n_averages} averages")
        if e is not None:
            lo, hi = e.band_hz
            if e.n_points:
                f0, f1 = e.compared_hz
                lines.append(
                    f"  frequency response {lo:g}-{hi:g} Hz ({e.n_points} points with "
                    f"coherence >= {e.min_coherence:g}, {f0:.4g}-{f1:.4g} Hz; {how}): "
                    "magnitude error max "
                    f"{e.max_magnitude_db:.3f} dB, rms {e.rms_magnitude_db:.3f} dB; "
                    f"phase error max {e.max_phase_deg:.2f} deg, rms {e.rms_phase_deg:.2f} deg"
                )
            else:
                lines.append(f"  frequency response {lo:g}-{hi:g} Hz: no point with "
                             f"coherence >= {e.min_coherence:g} ({how})")
        lines.append(
            f"  residuals white: {'yes' if r.white else 'no'} (Ljung-Box Q={r.ljung_box_q:.4g}, "
            f"p={r.ljung_box_p:.3g}); independent of input: "
            f"{'yes' if r.independent else 'no'}"
        )
        return "\n".join(lines)


def validate(
    model: _Model,
    u: ArrayLike,
    y: ArrayLike,
    *,
    fs: float,
    band_hz: tuple[float, float] | None = None,
    holdout: float | None = 0.3,
    min_coherence: float = 0.9,
    horizons: tuple[int, ...] = (1,),
    max_lag: int = 25,
    alpha: float = 0.01,
    nperseg: int | None = None,
    initial: str | None = None,
    frf_method: str = "auto",
) -> ValidationReport:
    """Validate ``model`` on the held-out end of a record, or on a separate record.

    Parameters
    ----------
    model : ArmaxModel
        The identified model (estimated on the first ``1 - holdout`` of the record).
    u, y : array_like, shape (n_samples,)
        The whole record (or the separate validation record): input and measured output,
        about the same operating point as the estimation data.
    fs : float
        Sample rate, Hz.
    band_hz : (float, float), optional
        Band for :func:`frf_error` and :func:`band_fit`; None skips both.
    holdout : float or None, default 0.3
        Fraction of the record at its end used for validation. None (or 0) validates on
        the whole record, for data kept apart from the estimation.
    min_coherence : float, default 0.9
        Passed to :func:`frf_error`.
    horizons : tuple of int, default (1,)
        Prediction horizons for :func:`prediction_fit`.
    max_lag, alpha : int, float
        Passed to :func:`residual_tests`.
    nperseg : int, optional
        Passed to :func:`ehss.frequency.frf_estimate`.
    initial : {"zero", "estimate", "warm"}, optional
        Start of the simulation (see :class:`ValidationReport`). Default ``"warm"`` with a
        holdout, ``"estimate"`` for a separate record.
    frf_method : {"auto", "welch", "dft"}, default "auto"
        Passed to :func:`ehss.frequency.frf_estimate`.

    Returns
    -------
    ValidationReport

    Raises
    ------
    DataError
        If the validation part is too short to validate.
    """
    u, y = as_record(u, y)
    if holdout is None or holdout == 0:
        start = 0
    else:
        holdout = check_real(holdout, "holdout", lo=0.0, hi=1.0, lo_open=True, hi_open=True)
        start = int(round(y.size * (1.0 - holdout)))
    if initial is None:
        initial = "warm" if start else "estimate"
    if initial not in ("zero", "estimate", "warm"):
        raise ParameterError(f"initial={initial!r} must be 'zero', 'estimate' or 'warm'")
    n_val = y.size - start
    if n_val < 64:
        raise DataError(f"the validation part has {n_val} samples; at least 64 are needed "
                        "(use a longer record or a larger holdout)")
    poles = np.asarray(model.poles())
    max_radius = float(np.max(np.abs(poles))) if poles.size else 0.0
    if initial == "warm":
        simulated = free_run(model, u, initial="zero")
    else:
        simulated = np.concatenate([
            np.asarray(model.simulate(u[:start]), dtype=np.float64) if start else np.zeros(0),
            free_run(model, u[start:], y[start:], initial=initial),
        ])
    sim_fit = nrmse_fit(y[start:], simulated[start:])
    bfit = None
    if band_hz is not None and 1.5 * float(band_hz[1]) < 0.45 * float(fs):
        bfit = band_fit(y[start:], simulated[start:], fs=fs, band_hz=band_hz)
    pred = {int(h): prediction_fit(model, u, y, int(h), start=start) for h in horizons}
    frf = frf_estimate(u[start:], y[start:], fs, method=frf_method, nperseg=nperseg,
                       band_hz=band_hz, min_coherence=min_coherence,
                       min_nperseg=segment_floor(model, n_val))
    err = None
    if band_hz is not None:
        err = frf_error(model, frf, band_hz=band_hz, min_coherence=min_coherence)
    res = residual_tests(model, u, y, max_lag=max_lag, alpha=alpha, start=start)
    return ValidationReport(
        n_estimation=start,
        n_validation=n_val,
        fs=float(fs),
        stable=bool(model.is_stable()),
        max_pole_radius=max_radius,
        initial_state=initial,
        simulation_fit_pct=sim_fit,
        band_fit_pct=bfit,
        prediction_fit_pct=pred,
        frf=frf,
        frf_error=err,
        residuals=res,
        simulated=simulated,
    )


def segment_floor(model: _Model, n_samples: int) -> int:
    """The shortest Welch segment that does not bias the estimate of ``model``'s loop.

    From the model's impulse response h over ``n_samples`` samples: its dead time d (the
    first sample where |h| reaches 1 % of its peak) and its memory m (the sample after
    the last where it does). The segment is at least 32 d (a dead time τ lowers the
    coherence by about (1 − τ/T)², here to 0.94 at worst) and 4 m (a resonance decays
    to 1 % in 4.6 time constants; a quarter of its half-power bandwidth, the resolution
    that resolves it, is 1/(4π τ), so 4 m ≥ 18 τ is enough; Bendat & Piersol, *Random
    Data*, ch. 9). An unstable model, or one whose response has not died out within the
    record, asks for ``n_samples``: the longest segment the record affords.

    Examples
    --------
    >>> from ehss.identification import ArmaxModel
    >>> segment_floor(ArmaxModel(a=[1.0, -0.5], b=[1.0], c=[1.0], delay=3), 10_000)
    96
    """
    h = np.asarray(model.simulate(np.r_[1.0, np.zeros(n_samples - 1)]), dtype=np.float64)
    peak = float(np.max(np.abs(h))) if np.all(np.isfinite(h)) else math.inf
    if not math.isfinite(peak) or not model.is_stable():
        return n_samples
    if peak == 0.0:
        return 1
    above = np.flatnonzero(np.abs(h) >= 0.01 * peak)
    return max(32 * int(above[0]), 4 * (int(above[-1]) + 1))


# -------------------------------------------------------------------------------- helpers


def _autocorr(x0: np.ndarray, max_lag: int) -> np.ndarray:
    """ρ(k) = Σ_{t≥k} x0(t) x0(t−k) / Σ x0², k = 0..max_lag, for zero-mean x0."""
    full = scipy.signal.correlate(x0, x0, mode="full", method="fft")
    mid = x0.size - 1
    r = full[mid : mid + max_lag + 1]
    return r / r[0]
