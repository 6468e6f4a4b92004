"""Excitation and test signals for the rig's three loops.

Every generator returns a :class:`Signal` sampled at ``fs`` in SI units (m for position,
m/s² for acceleration, N for force). Random generators take a ``seed`` and draw from
``numpy.random.default_rng(seed)``, never from the global generator, so a test is
reproduced exactly from its settings. :func:`check_feasible` tells, before a test is run,
whether a reference would leave the rig's limits (stroke, velocity, acceleration, force;
Table 2).

The paper's tests (PAPER.md §6): band-limited random displacement 2–100 Hz
(:func:`band_limited_random`), random acceleration 0.5 g 2–100 Hz, swept-sine force
25 ± 0.75 kgf 0–20 Hz (:func:`swept_sine`), and step tests (:func:`step`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, overload

import numpy as np
import scipy.signal
from numpy.typing import ArrayLike, DTypeLike, NDArray

from ehss._checks import check_band, check_fs, check_int, check_real
from ehss.control.discrete import generator_coefficients, generator_zoh
from ehss.errors import ParameterError
from ehss.params import GRAVITY_M_S2, RigParams

__all__ = [
    "Signal",
    "step",
    "sine",
    "band_limited_random",
    "swept_sine",
    "multisine",
    "earthquake",
    "with_fade",
    "check_feasible",
    "STROKE_MARGIN",
    "MAX_SAMPLES",
]

#: Fraction of the half stroke a position or implied displacement may use.
STROKE_MARGIN = 0.9


@dataclass(frozen=True, kw_only=True)
class Signal:
    """A sampled test signal.

    Attributes
    ----------
    values : ndarray, shape (n_samples,)
        Samples in SI units (read-only).
    fs : float
        Sample rate, Hz.
    kind : str
        Generator name (``"step"``, ``"sine"``, ...).
    settings : dict
        The generator's arguments and derived facts (e.g. the multisine's tone
        frequencies), enough to regenerate the signal.
    """

    values: NDArray[np.float64]
    fs: float
    kind: str
    settings: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        v = np.array(self.values, dtype=np.float64)
        if v.ndim != 1 or v.size < 1:
            raise ParameterError(f"values with shape {v.shape} must be a non-empty 1-D array")
        if not np.all(np.isfinite(v)):
            raise ParameterError("values must be finite")
        check_fs(self.fs)
        v.setflags(write=False)
        object.__setattr__(self, "values", v)
        object.__setattr__(self, "fs", float(self.fs))

    @property
    def t(self) -> NDArray[np.float64]:
        """Sample times, s, starting at 0."""
        return np.arange(self.values.size) / self.fs

    @property
    def duration_s(self) -> float:
        """Number of samples / fs."""
        return self.values.size / self.fs

    def __len__(self) -> int:
        return int(self.values.size)

    def __array__(self, dtype: DTypeLike | None = None,  # noqa: D105 - numpy protocol
                  copy: bool | None = None) -> np.ndarray:
        return np.asarray(self.values, dtype=dtype)


# --------------------------------------------------------------------------- checks
def _finite(name: str, value: Any) -> float:
    """A finite real (TypeError for another type, ParameterError for NaN/inf)."""
    return check_real(value, name)


def _positive(name: str, value: Any) -> float:
    """A finite real > 0."""
    return check_real(value, name, lo=0.0, lo_open=True)


#: Longest record a generator makes: 2e7 samples (5.5 h at 1 kHz). A closed-loop
#: simulation keeps about 25 columns of it, some 4 GB, within this machine class's memory.
MAX_SAMPLES = 20_000_000


def _n_samples(duration_s: float, fs: float) -> int:
    _positive("duration_s", duration_s)
    check_fs(fs)
    n = int(round(duration_s * fs))
    if n < 2:
        raise ParameterError(f"duration_s={duration_s!r} must give at least 2 samples at fs={fs!r}")
    if n > MAX_SAMPLES:
        raise ParameterError(
            f"duration_s={duration_s!r} at fs={fs!r} gives {n} samples; at most "
            f"{MAX_SAMPLES} are allowed (split the test into shorter records)"
        )
    return n


def _scale(x: NDArray[np.float64], rms: float | None,
           peak: float | None) -> NDArray[np.float64]:
    if (rms is None) == (peak is None):
        raise ParameterError(f"rms={rms!r}, peak={peak!r}: give exactly one of them")
    if rms is not None:
        return x * (_positive("rms", rms) / np.sqrt(np.mean(x**2)))
    return x * (_positive("peak", peak) / np.max(np.abs(x)))


def _fade_window(n: int, fs: float, fade_in_s: float, fade_out_s: float) -> NDArray[np.float64]:
    w = np.ones(n)
    for length_s, sl in ((fade_in_s, slice(None)), (fade_out_s, slice(None, None, -1))):
        m = int(round(length_s * fs))
        if m > 0:
            # raised cosine 0 → 1: (1 − cos(π k/m))/2, k = 0..m−1
            ramp = 0.5 * (1.0 - np.cos(np.pi * np.arange(m) / m))
            w[sl][:m] *= ramp
    return w


def _band_project(x: NDArray[np.float64], fs: float, lo: float,
                  hi: float) -> NDArray[np.float64]:
    spec = np.fft.rfft(x)
    f = np.fft.rfftfreq(x.size, 1.0 / fs)
    spec[(f < lo) | (f > hi)] = 0.0
    if lo > 0:
        spec[0] = 0.0
    return np.fft.irfft(spec, n=x.size)


def _zero_ends(x: NDArray[np.float64], fs: float, lo: float,
               hi: float) -> NDArray[np.float64]:
    """Subtract band-limited kernels so that x[0] = x[1] = x[-2] = x[-1] = 0."""
    n = x.size
    idx = [0, 1, n - 2, n - 1] if n >= 4 else list(range(n))
    kernels = np.array([_band_project(np.eye(1, n, i)[0], fs, lo, hi) for i in idx])
    coef = np.linalg.lstsq(kernels[:, idx].T, x[idx], rcond=None)[0]
    return x - coef @ kernels


# --------------------------------------------------------------------------- generators
@overload
def with_fade(
    signal: Signal, *, fs: float | None = None, fade_in_s: float = 0.1,
    fade_out_s: float = 0.1, offset: float = 0.0,
) -> Signal: ...
@overload
def with_fade(
    signal: ArrayLike, *, fs: float | None = None, fade_in_s: float = 0.1,
    fade_out_s: float = 0.1, offset: float = 0.0,
) -> NDArray[np.float64]: ...
def with_fade(
    signal: Signal | ArrayLike, *, fs: float | None = None, fade_in_s: float = 0.1,
    fade_out_s: float = 0.1, offset: float = 0.0,
) -> Signal | NDArray[np.float64]:
    """Apply raised-cosine fades to the part of a signal around ``offset``.

    Returns a :class:`Signal` for a Signal input (``fs`` taken from it), else an ndarray
    (``fs`` required).
    """
    if isinstance(signal, Signal):
        fs = signal.fs
        x = signal.values
    else:
        if fs is None:
            raise ParameterError("fs=None must be given for an array input")
        x = np.asarray(signal, dtype=np.float64)
    check_fs(fs)
    _finite("fade_in_s", fade_in_s)
    _finite("fade_out_s", fade_out_s)
    _finite("offset", offset)
    if fade_in_s < 0 or fade_out_s < 0 or (fade_in_s + fade_out_s) * fs > x.size:
        raise ParameterError(
            f"fade_in_s={fade_in_s!r}, fade_out_s={fade_out_s!r} must be >= 0 and fit in "
            f"the signal ({x.size / fs:.6g} s)"
        )
    y = offset + (x - offset) * _fade_window(x.size, fs, fade_in_s, fade_out_s)
    if isinstance(signal, Signal):
        settings = dict(signal.settings, fade_in_s=fade_in_s, fade_out_s=fade_out_s)
        return Signal(values=y, fs=fs, kind=signal.kind, settings=settings)
    return y


def step(
    amplitude: float, *, duration_s: float, fs: float, start_s: float = 0.1, offset: float = 0.0
) -> Signal:
    """Step of ``amplitude`` from ``offset`` at ``start_s``.

    Examples
    --------
    >>> s = step(0.01, duration_s=1.0, fs=1000.0)
    >>> s.values[99], s.values[100]
    (np.float64(0.0), np.float64(0.01))
    """
    n = _n_samples(duration_s, fs)
    a, off = _finite("amplitude", amplitude), _finite("offset", offset)
    start = _finite("start_s", start_s)
    if not 0 <= start < duration_s:
        raise ParameterError(f"start_s={start_s!r} must be in [0, duration_s={duration_s!r})")
    t = np.arange(n) / fs
    # samples at t ≥ start (with a half-sample tolerance against rounding of k/fs)
    x = np.where(t >= start - 0.5 / fs, off + a, off).astype(np.float64)
    return Signal(values=x, fs=fs, kind="step", settings=dict(
        amplitude=a, duration_s=duration_s, start_s=start, offset=off))


def sine(
    amplitude: float, freq_hz: float, *, duration_s: float, fs: float, offset: float = 0.0,
    ramp_s: float = 0.1,
) -> Signal:
    """Sine ``offset + amplitude·sin(2π f t)`` with a raised-cosine fade-in of ``ramp_s``."""
    n = _n_samples(duration_s, fs)
    a, off, f = _finite("amplitude", amplitude), _finite("offset", offset), _positive(
        "freq_hz", freq_hz)
    if f >= fs / 2:
        raise ParameterError(f"freq_hz={freq_hz!r} must be below fs/2 = {fs / 2!r}")
    ramp = _finite("ramp_s", ramp_s)
    if not 0 <= ramp <= duration_s:
        raise ParameterError(f"ramp_s={ramp_s!r} must be in [0, duration_s={duration_s!r}]")
    t = np.arange(n) / fs
    x = a * np.sin(2 * np.pi * f * t) * _fade_window(n, fs, ramp, 0.0)
    return Signal(values=off + x, fs=fs, kind="sine", settings=dict(
        amplitude=a, freq_hz=f, duration_s=duration_s, offset=off, ramp_s=ramp))


def band_limited_random(
    *, band_hz: tuple[float, float], duration_s: float, fs: float, seed: int | None,
    rms: float | None = None, peak: float | None = None, fade_s: float = 0.2,
    offset: float = 0.0,
) -> Signal:
    """Gaussian random signal with a flat spectrum inside ``band_hz``.

    Parameters
    ----------
    band_hz : (float, float)
        Pass band, 0 <= f_lo < f_hi < fs/2.
    duration_s, fs : float
    seed : int or None
        Seed of ``numpy.random.default_rng``.
    rms, peak : float
        Give exactly one: the RMS or the peak of the result (about ``offset``).
    fade_s : float
        Raised-cosine fade in and out, s.

    Notes
    -----
    White noise is projected on the band in the FFT domain (all bins outside the band
    set to zero), faded in and out, and projected again: the fade's own spectrum would
    otherwise leak out of the band. The second projection partly undoes the fade (the
    ends come back at a few % of the RMS), so band-limited kernels (projections of unit
    impulses at the first two and last two samples) are subtracted to make the first and
    last two samples exactly zero. The result is band-limited to rounding (as a periodic
    signal over the record) and starts and ends at rest.
    """
    n = _n_samples(duration_s, fs)
    lo, hi = check_band(band_hz, fs=fs, below_nyquist=True)
    fade = _finite("fade_s", fade_s)
    if not 0 <= 2 * fade <= duration_s:
        raise ParameterError(f"fade_s={fade_s!r} must be in [0, duration_s/2]")
    rng = np.random.default_rng(seed)
    x = _band_project(rng.standard_normal(n), fs, lo, hi)
    x = _band_project(x * _fade_window(n, fs, fade, fade), fs, lo, hi)
    x = _zero_ends(x, fs, lo, hi)
    if not np.any(x):
        raise ParameterError(f"band_hz={band_hz!r} holds no FFT bin at duration_s={duration_s!r}")
    x = _scale(x, rms, peak)
    off = _finite("offset", offset)
    return Signal(values=off + x, fs=fs, kind="band_limited_random", settings=dict(
        band_hz=(lo, hi), duration_s=duration_s, seed=seed, rms=rms, peak=peak,
        fade_s=fade, offset=off))


def swept_sine(
    amplitude: float, *, f0_hz: float, f1_hz: float, duration_s: float, fs: float,
    method: str = "linear", offset: float = 0.0,
) -> Signal:
    """Swept sine ``offset + amplitude·sin(φ(t))`` from f0 to f1 (scipy.signal.chirp).

    ``method="linear"``: f(t) = f0 + (f1 − f0) t/T (f0 = 0 allowed); ``"log"``:
    f(t) = f0 (f1/f0)^(t/T), f0 > 0. The sweep starts at phase 0, so it leaves the offset
    smoothly. The paper's force test is ``swept_sine(0.75*g, f0_hz=0, f1_hz=20,
    offset=25*g, ...)`` in newtons (25 ± 0.75 kgf).
    """
    n = _n_samples(duration_s, fs)
    a, off = _finite("amplitude", amplitude), _finite("offset", offset)
    f0, f1 = _finite("f0_hz", f0_hz), _finite("f1_hz", f1_hz)
    if method not in ("linear", "log"):
        raise ParameterError(f"method={method!r} must be 'linear' or 'log'")
    if not (0 <= f0 < fs / 2 and 0 < f1 < fs / 2):
        raise ParameterError(
            f"f0_hz={f0_hz!r}, f1_hz={f1_hz!r} must lie in [0, fs/2 = {fs / 2!r})"
        )
    if method == "log" and f0 <= 0:
        raise ParameterError(f"f0_hz={f0_hz!r} must be > 0 for method='log'")
    t = np.arange(n) / fs
    # cos(φ − 90°) = sin(φ): starts at zero
    x = scipy.signal.chirp(t, f0=f0, t1=duration_s, f1=f1,
                           method="linear" if method == "linear" else "logarithmic", phi=-90.0)
    return Signal(values=off + a * x, fs=fs, kind="swept_sine", settings=dict(
        amplitude=a, f0_hz=f0, f1_hz=f1, duration_s=duration_s, method=method, offset=off))


def multisine(
    *, band_hz: tuple[float, float], duration_s: float, fs: float, seed: int | None = None,
    rms: float | None = None, peak: float | None = None, n_tones: int | None = None,
    offset: float = 0.0,
) -> Signal:
    """Periodic multisine with Schroeder phases, tones on the record's FFT grid.

    The record (``round(duration_s·fs)`` samples) is exactly one period: tone k has
    frequency k·fs/n with k inside ``band_hz``, so the DFT of the record (or of any whole
    number of periods) has no leakage. ``n_tones`` spreads that many tones evenly over the
    available bins (all of them when None). Phases φ_k = −π k(k − 1)/K (Schroeder) keep the
    crest factor low; ``seed`` (optional) adds a random circular shift so that repeated
    tests differ, without changing the spectrum.

    The tone frequencies are in ``settings["freq_hz"]``.
    """
    n = _n_samples(duration_s, fs)
    lo, hi = check_band(band_hz, fs=fs, below_nyquist=True)
    f = np.fft.rfftfreq(n, 1.0 / fs)
    bins = np.nonzero((f >= lo) & (f <= hi) & (f > 0))[0]
    if bins.size == 0:
        raise ParameterError(
            f"band_hz={band_hz!r} holds no frequency of the grid fs/n = {fs / n!r} Hz"
        )
    if n_tones is not None:
        n_tones = check_int(n_tones, "n_tones", lo=1, hi=int(bins.size))
        bins = bins[np.unique(np.round(np.linspace(0, bins.size - 1, n_tones)).astype(int))]
    k_tones = bins.size
    idx = np.arange(1, k_tones + 1)
    phase = -np.pi * idx * (idx - 1) / k_tones
    spec = np.zeros(f.size, dtype=complex)
    spec[bins] = np.exp(1j * phase)
    x = np.fft.irfft(spec, n=n)
    if seed is not None:
        x = np.roll(x, int(np.random.default_rng(seed).integers(n)))
    x = _scale(x, rms, peak)
    off = _finite("offset", offset)
    return Signal(values=off + x, fs=fs, kind="multisine", settings=dict(
        band_hz=(lo, hi), duration_s=duration_s, seed=seed, rms=rms, peak=peak,
        n_tones=k_tones, freq_hz=f[bins].tolist(), offset=off))


def earthquake(
    *, duration_s: float, fs: float, seed: int | None, peak_m_s2: float,
    ground_freq_hz: float = 2.5, ground_damping: float = 0.6, rise_s: float | None = None,
    strong_s: float | None = None, decay_rate_per_s: float | None = None,
    highpass_hz: float = 0.2,
) -> Signal:
    """Synthetic ground acceleration: Kanai–Tajimi filtered white noise with an envelope.

    Parameters
    ----------
    duration_s, fs : float
    seed : int or None
    peak_m_s2 : float
        Peak ground acceleration of the result.
    ground_freq_hz, ground_damping : float
        ωg/2π and ζg of the Kanai–Tajimi filter
        H(s) = (2ζg ωg s + ωg²)/(s² + 2ζg ωg s + ωg²).
    rise_s, strong_s, decay_rate_per_s : float
        Envelope: (t/rise)³ build-up, constant strong motion, then exp(−c (t − t2)),
        and a raised-cosine fade over the last 5 % (at most 0.5 s).
        Defaults: 15 % and 35 % of the duration, c = 5/(remaining time).
    highpass_hz : float
        Corner of the zero-phase baseline-correcting high-pass (4th order Butterworth
        magnitude, applied in the FFT domain), the baseline correction that keeps the
        displacement inside the stroke.

    Notes
    -----
    The shaped noise is turned into a displacement (divided by s² in the FFT domain),
    the envelope is applied to that displacement, and the acceleration is its exact
    second derivative. The record therefore starts and ends at rest and its double
    integral has no drift; its peak is ``settings["peak_displacement_m"]``.
    :func:`check_feasible` checks the displacement the acceleration loop's generator
    (eq 10) will demand.
    """
    n = _n_samples(duration_s, fs)
    pk = _positive("peak_m_s2", peak_m_s2)
    fg, zg = _positive("ground_freq_hz", ground_freq_hz), _positive("ground_damping",
                                                                     ground_damping)
    hp = _positive("highpass_hz", highpass_hz)
    if not (fg < fs / 2 and hp < fg):
        raise ParameterError(
            f"ground_freq_hz={ground_freq_hz!r} must be below fs/2 and above "
            f"highpass_hz={highpass_hz!r}"
        )
    t1 = 0.15 * duration_s if rise_s is None else _positive("rise_s", rise_s)
    ts = 0.35 * duration_s if strong_s is None else _positive("strong_s", strong_s)
    if t1 + ts >= duration_s:
        raise ParameterError(
            f"rise_s={t1!r} + strong_s={ts!r} must be shorter than duration_s={duration_s!r}"
        )
    t2 = t1 + ts
    c = 5.0 / (duration_s - t2) if decay_rate_per_s is None else _positive(
        "decay_rate_per_s", decay_rate_per_s)
    rng = np.random.default_rng(seed)
    spec = np.fft.rfft(rng.standard_normal(n))
    f = np.fft.rfftfreq(n, 1.0 / fs)
    s = 2j * np.pi * f
    wg = 2 * np.pi * fg
    # Kanai–Tajimi: H(s) = (2ζg ωg s + ωg²)/(s² + 2ζg ωg s + ωg²)
    spec *= (2 * zg * wg * s + wg**2) / (s**2 + 2 * zg * wg * s + wg**2)
    # zero-phase high-pass |H|² = (f/fc)^8 / (1 + (f/fc)^8): 4th-order Butterworth, twice
    r8 = (f / hp) ** 8
    spec *= r8 / (1.0 + r8)
    # work on the displacement D = A/s² (DC removed), so that the envelope is applied to
    # a displacement that starts and ends at rest; the acceleration is its exact (FFT)
    # second derivative and integrates back to it without drift
    spec[0] = 0.0
    spec[1:] /= s[1:] ** 2
    d = np.fft.irfft(spec, n=n)
    t = np.arange(n) / fs
    # build-up (t/t1)³ (zero value, slope and curvature at t = 0), strong motion, decay
    env = np.where(t < t1, (t / t1) ** 3, np.where(t < t2, 1.0, np.exp(-c * (t - t2))))
    fade = min(0.5, 0.05 * duration_s)
    d = d * env * _fade_window(n, fs, 0.0, fade)
    x = np.fft.irfft(np.fft.rfft(d) * s**2, n=n)
    scale = pk / np.max(np.abs(x))
    x *= scale
    d *= scale
    return Signal(values=x, fs=fs, kind="earthquake", settings=dict(
        duration_s=duration_s, seed=seed, peak_m_s2=pk, ground_freq_hz=fg,
        ground_damping=zg, rise_s=t1, strong_s=ts, decay_rate_per_s=c, highpass_hz=hp,
        peak_displacement_m=float(np.max(np.abs(d)))))


# --------------------------------------------------------------------------- feasibility
def _generator_response(a_r: NDArray[np.float64], params: RigParams,
                        fs: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """r_d, v_d of the acceleration generator eq (10), ZOH-discretised at fs."""
    t = params.acceleration
    wg, dg = generator_coefficients(t)
    # [r_d, v_d][k+1] = Φ [r_d, v_d][k] + Γ a_r[k], the controller's own discretisation
    phi, gamma = generator_zoh(t.kg, wg, dg, 1.0 / fs)
    # that recursion from rest as one transfer function per output, which lfilter runs
    # in C (a loop over the samples in Python would take seconds on long tests)
    num, den = scipy.signal.ss2tf(phi, gamma[:, None], np.eye(2), np.zeros((2, 1)))
    return scipy.signal.lfilter(num[0], den, a_r), scipy.signal.lfilter(num[1], den, a_r)


def check_feasible(
    values: Signal | ArrayLike, loop: str, params: RigParams, fs: float | None = None, *,
    stroke_margin: float = STROKE_MARGIN,
) -> dict[str, float]:
    """Raise :class:`ParameterError` if a reference would leave the rig's limits.

    Parameters
    ----------
    values : Signal or ndarray, shape (n_samples,)
        Reference of the loop in SI units (m, m/s², N).
    loop : {"position", "acceleration", "force"}
    params : RigParams
    fs : float
        Sample rate (taken from a Signal when omitted).
    stroke_margin : float
        Fraction of the half stroke a displacement may use.

    Returns
    -------
    dict
        The peaks that were checked (``peak_displacement_m``, ``peak_velocity_m_s``, ...).

    Notes
    -----
    position: |r| ≤ margin·stroke, |ṙ| (finite differences) ≤ Table 2's velocity and the
    valve's no-load velocity K0. acceleration: |a| ≤ Table 2's acceleration; the
    displacement and velocity the generator of eq (10) makes of it must respect the same
    stroke and velocity limits. force: |F| ≤ Table 2's force and ≤ 2/3·Ap·Ps (rated load
    pressure, where the valve keeps 1/√3 of its no-load flow).
    """
    x, fs = _values_and_rate(values, fs)
    if x.ndim != 1 or x.size < 2 or not np.all(np.isfinite(x)):
        raise ParameterError("values must be a finite 1-D array of at least 2 samples")
    if not 0 < stroke_margin <= 1:
        raise ParameterError(f"stroke_margin={stroke_margin!r} must be in (0, 1]")
    if loop == "position":
        return _check_motion(x, np.diff(x) * fs, "position reference", params, stroke_margin)
    if loop == "acceleration":
        return _check_acceleration(x, params, fs, stroke_margin)
    if loop == "force":
        return _check_force(x, params)
    raise ParameterError(f"loop={loop!r} must be one of ['position', 'acceleration', 'force']")


def _values_and_rate(values: Signal | ArrayLike,
                     fs: float | None) -> tuple[NDArray[np.float64], float]:
    """The samples of a reference and its rate (a Signal's own unless ``fs`` is given)."""
    if isinstance(values, Signal):
        fs = values.fs if fs is None else fs
        x = values.values
    else:
        x = np.asarray(values, dtype=np.float64)
    if fs is None:
        raise ParameterError("fs=None must be given for an array input")
    check_fs(fs)
    return x, fs


def _check_motion(d: NDArray[np.float64], v: NDArray[np.float64], what: str,
                  params: RigParams, stroke_margin: float) -> dict[str, float]:
    """Peak displacement within the stroke margin, peak velocity within Table 2's and the
    valve's no-load velocity."""
    lim = params.limits
    stroke = stroke_margin * params.actuator.stroke_m
    v_max = min(lim.max_velocity_m_s, params.max_velocity_m_s)
    v_name = ("limits.max_velocity_m_s" if lim.max_velocity_m_s <= params.max_velocity_m_s
              else "the valve's no-load velocity")
    pd, pv = float(np.max(np.abs(d))), float(np.max(np.abs(v)))
    if pd > stroke:
        raise ParameterError(
            f"{what} peak displacement {pd:.4g} m exceeds {stroke_margin:.0%} of the "
            f"stroke ({stroke:.4g} m of actuator.stroke_m={params.actuator.stroke_m!r})"
        )
    if pv > v_max:
        raise ParameterError(
            f"{what} peak velocity {pv:.4g} m/s exceeds {v_name} ({v_max:.4g} m/s)"
        )
    return {"peak_displacement_m": pd, "peak_velocity_m_s": pv}


def _check_acceleration(x: NDArray[np.float64], params: RigParams, fs: float,
                        stroke_margin: float) -> dict[str, float]:
    """Peak acceleration within Table 2's, and the motion eq (10)'s generator makes of it
    within the stroke and velocity limits."""
    lim = params.limits
    pa = float(np.max(np.abs(x)))
    if pa > lim.max_acceleration_m_s2:
        raise ParameterError(
            f"acceleration reference peak {pa:.4g} m/s² ({pa / GRAVITY_M_S2:.3g} g) exceeds "
            f"limits.max_acceleration_m_s2={lim.max_acceleration_m_s2:.4g}"
        )
    r_d, v_d = _generator_response(x, params, fs)
    return {"peak_acceleration_m_s2": pa,
            **_check_motion(r_d, v_d, "generated (eq 10) displacement reference", params,
                            stroke_margin)}


def _check_force(x: NDArray[np.float64], params: RigParams) -> dict[str, float]:
    """Peak force within Table 2's and 2/3·Ap·Ps (the rated load pressure)."""
    lim = params.limits
    pf = float(np.max(np.abs(x)))
    rated = 2.0 / 3.0 * params.max_actuator_force_n
    if pf > lim.max_force_n:
        raise ParameterError(
            f"force reference peak {pf:.4g} N exceeds limits.max_force_n={lim.max_force_n:.4g}"
        )
    if pf > rated:
        raise ParameterError(
            f"force reference peak {pf:.4g} N exceeds 2/3·Ap·Ps = {rated:.4g} N "
            "(rated load pressure)"
        )
    return {"peak_force_n": pf}
