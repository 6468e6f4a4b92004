"""Inverse-model feed-forward design: ZPETC and ZMETC with preview and a band limit.

An identified closed loop (reference → measured output) is the ARMAX deterministic part

.. math:: G(q^{-1}) = q^{-d}\\,\\frac{B(q^{-1})}{A(q^{-1})}

of eq (16) of the paper. Its inverse is what the identification is for: a drive
``u = G^{-1} r`` makes the loop output follow the reference ``r``. Two things stop a naive
inversion: the delay ``q^{-d}`` (inverting it needs future samples) and zeros of ``B``
outside or near the unit circle (their inverse is unstable or rings). Because the whole
drive file is known in advance, the delay is inverted exactly by *preview* (a non-causal
advance), and the bad zeros are handled by one of two classic approximations:

* **ZPETC** (Tomizuka 1987, zero-phase-error tracking controller). Factor
  ``B = k B_s B_u`` into cancellable zeros ``B_s`` (inside the unit circle and well damped)
  and the rest ``B_u`` of degree ``s``. The inverse is

  .. math:: F(q) = q^{d+s}\\,\\frac{A(q^{-1})\\,B_u^*(q^{-1})}{k\\,B_s(q^{-1})\\,B_u(1)^2},

  with ``B_u^*`` the coefficient-reversed ``B_u``. The overall response
  ``G F = B_u(q^{-1}) B_u(q) / B_u(1)^2`` has zero phase at every frequency, unit gain at DC
  and the magnitude ``|B_u(e^{jω})|^2 / B_u(1)^2``.
* **ZMETC** (zero-magnitude-error tracking controller). Unstable zeros are mirrored inside
  the unit circle, ``B_u → B_u^*``:

  .. math:: F(q) = q^{d+p}\\,\\frac{A(q^{-1})}{k\\,B_s(q^{-1})\\,B_u^*(q^{-1})},

  so that ``G F = q^{p} B_u(q^{-1}) / B_u^*(q^{-1})`` is an all-pass: the magnitude is
  exactly 1 and a phase error remains. The extra preview ``p`` is the integer advance that
  best cancels the all-pass's linear phase (over the band, or at DC without a band).

Leading exact zeros of ``b`` are extra delay and are added to the preview. The band limit
is a zero-phase raised-cosine taper applied by FFT to the reference before the inversion:
unity inside ``[lo, hi]``, smoothly to zero at ``lo/2`` and at ``cutoff_hz``, exactly zero
beyond, so the inverse cannot amplify noise above the identified band.

**Known factors.** Part of a closed loop may be known exactly and need not be identified:
the acceleration loop's reference first passes the controller's acceleration generator,
eq (10), GAR·s² = Kg s²/(s² + ωg s + δg) (discretised with a zero-order hold as the
controller runs it), and the output is measured through the accelerometer's AC coupling
s/(s + ωa) (:mod:`ehss.identification.known`). Both are slow high-passes near 0.5 Hz that
a 2–100 Hz identification test hardly excites, yet they give the loop tens of degrees of
phase lead at 1–2 Hz. The loop is then modelled as ``G = G_rest · F`` with
``F = N(q^-1)/D(q^-1)`` known and ``G_rest`` identified from ``F a_r`` to the output, and
the compensator is ``G_rest^{-1} ∘ F^{-1}``. ``F`` has zeros at or next to ``z = 1``, so
its inverse grows without bound towards DC and is never run as a recursive filter: it is
applied in the frequency domain together with the band limit,
``R_band(f) = R(f) · W(f) / F(e^{j2πf dt})``, and the band limit's zero below ``lo/2``
removes the content where ``1/F`` grows (the design checks that ``|F|`` does not vanish
where ``W > 0``). ``G_rest^{-1}`` (ZPETC or ZMETC) then acts on ``R_band`` as before.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.fft
import scipy.signal

from ehss._checks import as_signal
from ehss.errors import ParameterError

__all__ = [
    "InverseModel",
    "METHODS",
    "design_inverse",
    "design_inverse_tf",
    "band_taper",
    "zpetc_magnitude",
    "zmetc_phase",
]

METHODS = ("zpetc", "zmetc")

#: Zeros closer than this to the unit circle cannot be inverted nor mirrored.
_UNIT_CIRCLE_TOL = 1e-9


# --------------------------------------------------------------------------- helpers
def _poly_from_roots_ascending(roots: np.ndarray) -> np.ndarray:
    """Coefficients ``[1, c1, .., cm]`` of ``prod(1 - r q^-1)`` in ascending powers of q^-1."""
    if roots.size == 0:
        return np.ones(1)
    c = np.poly(roots)
    return np.ascontiguousarray(np.real_if_close(c, tol=1e6).real, dtype=float)


def _eval_ascending(coef: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Evaluate ``sum coef[i] x**i`` (``x = e^{-jωdt}`` gives a polynomial in q^-1)."""
    return np.polynomial.polynomial.polyval(x, coef)


def _zero_damping(z: np.ndarray, ) -> np.ndarray:
    """Damping ratio of the continuous mode ``s = ln z / dt`` of each zero (dt cancels)."""
    s = np.log(z.astype(complex))
    mag = np.abs(s)
    with np.errstate(invalid="ignore", divide="ignore"):
        zeta = np.where(mag > 0, -s.real / np.where(mag > 0, mag, 1.0), 1.0)
    return zeta


def band_taper(freq_hz: np.ndarray, band_hz: tuple[float, float] | None,
               cutoff_hz: float | None) -> np.ndarray:
    """Real, zero-phase gain of the band limit (raised-cosine edges).

    Unity on ``[lo, hi]``; from ``hi`` to ``cutoff_hz`` a raised cosine down to exactly 0;
    below ``lo`` a raised cosine from 1 at ``lo`` to 0 at ``lo/2`` (only when ``lo > 0``).
    """
    f = np.abs(np.asarray(freq_hz, dtype=float))
    if band_hz is None:
        return np.ones_like(f)
    lo, hi = band_hz
    w = np.ones_like(f)
    if cutoff_hz is not None and cutoff_hz > hi:
        x = np.clip((f - hi) / (cutoff_hz - hi), 0.0, 1.0)
        w *= 0.5 * (1.0 + np.cos(np.pi * x))
    if lo > 0.0:
        x = np.clip((lo - f) / (0.5 * lo), 0.0, 1.0)
        w *= 0.5 * (1.0 + np.cos(np.pi * x))
    return w


def zpetc_magnitude(b_u: np.ndarray, freq_hz: np.ndarray, dt: float) -> np.ndarray:
    """Analytic ZPETC overall gain ``|B_u(e^{-jω dt})|^2 / B_u(1)^2`` (zero phase)."""
    x = np.exp(-2j * np.pi * np.asarray(freq_hz, dtype=float) * dt)
    return np.abs(_eval_ascending(b_u, x)) ** 2 / np.sum(b_u) ** 2


def zmetc_phase(b_u: np.ndarray, extra_preview: int, freq_hz: np.ndarray,
                dt: float) -> np.ndarray:
    """Analytic ZMETC overall phase (rad): ``arg(B_u(e^{-jωdt}) / B_u^*(e^{-jωdt})) + ω dt p``."""
    w = 2.0 * np.pi * np.asarray(freq_hz, dtype=float) * dt
    x = np.exp(-1j * w)
    ratio = _eval_ascending(b_u, x) / _eval_ascending(b_u[::-1], x)
    return np.angle(ratio * np.exp(1j * w * extra_preview))


# --------------------------------------------------------------------------- result
@dataclass(frozen=True, kw_only=True)
class InverseModel:
    """A designed feed-forward inverse of a closed-loop model (ZPETC or ZMETC).

    The drive is ``u(k) = v(k + preview)``, ``v = lfilter(num, den, r_band)``, with
    ``r_band`` the band-limited reference.

    Attributes
    ----------
    method : {"zpetc", "zmetc"}
    num, den : ndarray
        Causal filter in ascending powers of q^-1 (``den[0] == 1``).
    preview : int
        Samples of advance (non-causal part): model delay + leading zero b's + ``s`` (ZPETC)
        or + the all-pass advance (ZMETC).
    dt : float
        Sample period (s).
    b_u : ndarray
        The uncancelled factor ``B_u`` (ascending powers of q^-1, ``[1.]`` if none).
    extra_preview : int
        Advance beyond the model delay for ``B_u`` (``s`` for ZPETC).
    band_hz : (float, float) or None
        Pass band ``(lo, hi)`` of the band limit; ``None`` for no band limit.
    cutoff_hz : float or None
        Above this frequency the band limit is exactly zero.
    cancelled_zeros, uncancelled_zeros, poles : ndarray
        Zeros cancelled exactly, zeros handled by the ZPETC/ZMETC factor, model poles.
    model_delay : int
        Total model delay (``delay`` plus leading zero b's).
    known_num, known_den : ndarray
        Known factor ``F = N/D`` in series with the inverted model (ascending powers of
        q^-1; ``[1.]`` and ``[1.]`` for none). Its inverse is applied in the frequency
        domain with the band limit (see the module notes).
    """

    method: str
    num: np.ndarray
    den: np.ndarray
    preview: int
    dt: float
    b_u: np.ndarray
    extra_preview: int
    band_hz: tuple[float, float] | None = None
    cutoff_hz: float | None = None
    cancelled_zeros: np.ndarray = field(default_factory=lambda: np.zeros(0, complex))
    uncancelled_zeros: np.ndarray = field(default_factory=lambda: np.zeros(0, complex))
    poles: np.ndarray = field(default_factory=lambda: np.zeros(0, complex))
    model_delay: int = 0
    known_num: np.ndarray = field(default_factory=lambda: np.ones(1))
    known_den: np.ndarray = field(default_factory=lambda: np.ones(1))

    @property
    def has_known(self) -> bool:
        """Whether a known factor ``F`` other than 1 is inverted too."""
        return not (self.known_num.size == 1 and self.known_den.size == 1
                    and self.known_num[0] == self.known_den[0])

    def known_response(self, freq_hz: np.ndarray) -> np.ndarray:
        """Complex response of the known factor ``F = N/D`` at ``freq_hz``."""
        x = np.exp(-2j * np.pi * np.asarray(freq_hz, dtype=float) * self.dt)
        return _eval_ascending(self.known_num, x) / _eval_ascending(self.known_den, x)

    @property
    def fs(self) -> float:
        """Sample rate (Hz)."""
        return 1.0 / self.dt

    # ---------------------------------------------------------------- responses
    def band_response(self, freq_hz: np.ndarray) -> np.ndarray:
        """Real gain of the band limit at ``freq_hz``."""
        return band_taper(freq_hz, self.band_hz, self.cutoff_hz)

    def frequency_response(self, freq_hz: np.ndarray, *, band: bool = True) -> np.ndarray:
        """Complex response of the inverse: ``e^{jω dt preview} num/den`` (× band limit).

        Parameters
        ----------
        freq_hz : array_like
            Frequencies (Hz).
        band : bool
            Include the band limit (default).
        """
        f = np.asarray(freq_hz, dtype=float)
        w = 2.0 * np.pi * f * self.dt
        x = np.exp(-1j * w)
        h = _eval_ascending(self.num, x) / _eval_ascending(self.den, x)
        h = h * np.exp(1j * w * self.preview)
        if self.has_known:
            with np.errstate(divide="ignore", invalid="ignore"):
                h = h / self.known_response(f)
        if band:
            h = h * self.band_response(f)
            if self.has_known:
                h = np.where(self.band_response(f) > 0.0, h, 0.0)
        return h

    def design_response(self, freq_hz: np.ndarray) -> np.ndarray:
        """Analytic overall response ``G·F`` the design aims at (no band limit).

        A known factor is cancelled exactly and does not appear here.

        ZPETC: ``|B_u|^2 / B_u(1)^2`` (real, non-negative); ZMETC: ``e^{jφ}`` with φ from
        :func:`zmetc_phase`.
        """
        f = np.asarray(freq_hz, dtype=float)
        if self.method == "zpetc":
            return zpetc_magnitude(self.b_u, f, self.dt).astype(complex)
        return np.exp(1j * zmetc_phase(self.b_u, self.extra_preview, f, self.dt))

    # ---------------------------------------------------------------- apply
    def apply(self, reference: Any, *, preview: int | None = None) -> np.ndarray:
        """Drive that makes the modelled loop follow ``reference``.

        Parameters
        ----------
        reference : array_like, shape (n_samples,)
            Reference sampled at ``1/dt``. For an exact result it should start at rest
            (zero over the first ``preview`` samples); after its end it is held at its
            last value for the preview.
        preview : int, optional
            Future reference samples the compensator may use. ``None`` (default) means the
            whole file is known and the full designed preview is used. With less preview
            the drive is causal up to that advance and the tracking lags by the
            difference.

        Returns
        -------
        drive : ndarray, shape (n_samples,)

        Raises
        ------
        DataError
            Empty, non-1-D or non-finite reference.
        ParameterError
            Negative ``preview``.
        """
        r = _as_reference(reference)
        advance = self.preview
        if preview is not None:
            if isinstance(preview, bool) or not isinstance(preview, (int, np.integer)) \
                    or preview < 0:
                raise ParameterError(f"preview={preview!r} must be a non-negative integer")
            advance = min(int(preview), self.preview)
        if self.band_hz is not None:
            shape = None
            if self.has_known:
                def shape(f: np.ndarray) -> np.ndarray:
                    w = band_taper(f, self.band_hz, self.cutoff_hz)
                    with np.errstate(divide="ignore", invalid="ignore"):
                        return np.where(w > 0.0, w / self.known_response(f), 0.0)
            padded, npad = _fft_band_limit(r, self.dt, self.band_hz, self.cutoff_hz, shape,
                                           padded=True)
            # The band limit is non-causal: the limited reference rings a little before
            # the record starts and after it ends. The inverse filter runs over that
            # lead-in (starting at rest far before t = 0) and its preview reads the
            # limited continuation, so the drive starts without the jump a recursive
            # inverse would give to a reference that does not start exactly at rest.
            r_ext = padded[: npad + r.size + advance]
            v = scipy.signal.lfilter(self.num, self.den, r_ext)
            return np.ascontiguousarray(v[npad + advance: npad + advance + r.size])
        # r(k) held at its last value after the end: the preview needs r(N..N+p-1).
        r_ext = np.concatenate([r, np.full(advance, r[-1])])
        v = scipy.signal.lfilter(self.num, self.den, r_ext)
        # u(k) = v(k + preview): the non-causal advance that inverts q^-d (and q^-s).
        return np.ascontiguousarray(v[advance:])


# --------------------------------------------------------------------------- design
def _as_reference(reference: Any) -> np.ndarray:
    data = getattr(reference, "values", None)
    if data is None:
        data = getattr(reference, "data", reference)
    return as_signal(data, "reference")


def _fft_band_limit(r: np.ndarray, dt: float, band_hz: tuple[float, float],
                    cutoff_hz: float | None, shape: Any = None, *, padded: bool = False
                    ) -> Any:
    """Zero-phase band limit by FFT with constant-extended padding (no wrap-around).

    ``shape(freq_hz) -> complex`` replaces the band taper when given (band limit times
    the inverse of a known factor); it must vanish wherever the taper does. With
    ``padded=True`` returns ``(y, npad)``: the limited signal with ``npad`` samples of
    lead-in before the record and at least ``npad`` after it.
    """
    lo, hi = band_hz
    widths = [w for w in ((cutoff_hz - hi) if cutoff_hz else 0.0, 0.5 * lo) if w > 0]
    width = min(widths) if widths else 1.0 / (r.size * dt)
    # The taper's impulse response decays within a few 1/width: pad by 8/width each side.
    npad = int(min(max(math.ceil(8.0 / (width * dt)), 16), 4 * r.size + 16))
    x = np.concatenate([np.full(npad, r[0]), r, np.full(npad, r[-1])])
    n = scipy.fft.next_fast_len(x.size + npad, real=True)
    # Pad the circular buffer with a smooth return from r[-1] to r[0] (half cosine).
    gap = n - x.size
    ramp = r[-1] + (r[0] - r[-1]) * 0.5 * (1.0 - np.cos(np.pi * np.arange(gap) / max(gap, 1)))
    x = np.concatenate([x, ramp])
    spec = scipy.fft.rfft(x)
    freq = scipy.fft.rfftfreq(n, dt)
    spec *= band_taper(freq, band_hz, cutoff_hz) if shape is None else shape(freq)
    y = scipy.fft.irfft(spec, n)
    if padded:
        return y, npad
    return np.ascontiguousarray(y[npad:npad + r.size])


def _check_band(band_hz: Any, cutoff_hz: float | None, fs: float
                ) -> tuple[tuple[float, float] | None, float | None]:
    if band_hz is None:
        if cutoff_hz is not None:
            raise ParameterError("cutoff_hz needs band_hz")
        return None, None
    try:
        lo, hi = (float(v) for v in band_hz)
    except (TypeError, ValueError):
        raise ParameterError(f"band_hz={band_hz!r} must be a pair (lo, hi) in Hz") from None
    nyq = 0.5 * fs
    if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 <= lo < hi < nyq):
        raise ParameterError(
            f"band_hz=({lo:g}, {hi:g}) must satisfy 0 <= lo < hi < fs/2 = {nyq:g} Hz"
        )
    if cutoff_hz is None:
        cutoff_hz = min(1.5 * hi, hi + 0.5 * (nyq - hi))
    cutoff_hz = float(cutoff_hz)
    if not hi < cutoff_hz <= nyq:
        raise ParameterError(f"cutoff_hz={cutoff_hz:g} must be in (hi={hi:g}, fs/2={nyq:g}] Hz")
    return (lo, hi), cutoff_hz


def design_inverse_tf(
    b: Any,
    a: Any,
    *,
    delay: int,
    dt: float,
    method: str = "zpetc",
    band_hz: tuple[float, float] | None = None,
    cutoff_hz: float | None = None,
    max_zero_radius: float = 0.999,
    min_zero_damping: float = 0.1,
    fast_zero_radius: float = 0.5,
    known: tuple[Any, Any] | None = None,
) -> InverseModel:
    """Design the inverse of ``G = q^-delay B(q^-1)/A(q^-1)`` (ZPETC or ZMETC).

    Parameters
    ----------
    b : array_like, shape (nb + 1,)
        ``[b0 .. b_nb]``, ``b_i`` multiplies ``u(k - delay - i)``.
    a : array_like, shape (na + 1,)
        ``[1, a1 .. a_na]``; must be stable.
    delay : int
        Model delay ``d >= 0`` (samples).
    dt : float
        Sample period (s).
    method : {"zpetc", "zmetc"}
        How the uncancellable zeros are handled (see the module notes).
    band_hz : (lo, hi), optional
        Pass band of the zero-phase band limit (Hz); ``None`` for none.
    cutoff_hz : float, optional
        Where the high-side taper reaches zero; default ``min(1.5 hi, (hi + fs/2)/2)``.
    max_zero_radius : float
        Zeros with ``|z|`` above this are never cancelled exactly.
    min_zero_damping : float
        Zeros whose continuous-equivalent mode ``ln(z)/dt`` has a damping ratio below this
        are badly damped and not cancelled (ZPETC) ...
    fast_zero_radius : float
        ... unless ``|z| <= fast_zero_radius`` (their mode dies out within a few samples).
        ZMETC cancels every zero inside the unit circle and mirrors only the unstable ones.
    known : (num, den), optional
        Known factor ``F = num/den`` (ascending powers of q^-1) in series with the model:
        the loop is ``G·F`` and the inverse ``G^-1 F^-1``, with ``F^-1`` applied in the
        frequency domain inside the band limit (see the module notes). Needs ``band_hz``;
        ``|F|`` must not vanish where the band limit is non-zero (e.g. the acceleration
        loop's high-passes need ``lo > 0``).

    Returns
    -------
    InverseModel

    Raises
    ------
    ParameterError
        Unstable poles (the message names the max pole radius), ``b`` all zero, non-finite
        coefficients, zeros on the unit circle, a bad method, band or dt.
    """
    if method not in METHODS:
        raise ParameterError(f"method={method!r} must be one of {METHODS}")
    try:
        b = np.atleast_1d(np.asarray(b, dtype=float)).ravel()
        a = np.atleast_1d(np.asarray(a, dtype=float)).ravel()
    except (TypeError, ValueError) as exc:
        raise ParameterError(f"model coefficients must be numbers: {exc}") from None
    if not (isinstance(dt, (int, float, np.floating)) and math.isfinite(dt) and dt > 0):
        raise ParameterError(f"model dt={dt!r} must be a positive number of seconds")
    if isinstance(delay, bool) or not isinstance(delay, (int, np.integer)) or delay < 0:
        raise ParameterError(f"model delay={delay!r} must be a non-negative integer")
    if not (np.all(np.isfinite(b)) and np.all(np.isfinite(a))):
        raise ParameterError("model coefficients must be finite (got NaN or inf in a or b)")
    if a.size == 0 or a[0] == 0.0:
        raise ParameterError(f"model a={a.tolist()!r} must start with a non-zero a0 (normally 1)")
    a = a / a[0]
    scale = np.max(np.abs(b)) if b.size else 0.0
    if scale == 0.0:
        raise ParameterError("model b is all zero: the model has no input path to invert")
    band, cutoff = _check_band(band_hz, cutoff_hz, 1.0 / dt)

    # Poles must be stable: A(q^-1) goes into the numerator of the inverse, but an
    # unstable model means the identification failed and its inverse is meaningless.
    poles = np.roots(a) if a.size > 1 else np.zeros(0, complex)
    if poles.size:
        rmax = float(np.max(np.abs(poles)))
        if rmax >= 1.0:
            raise ParameterError(
                f"model is unstable: max pole radius {rmax:.6g} >= 1; an unstable closed-loop "
                "model cannot be inverted (re-identify it, e.g. with more data or a lower order)"
            )

    # Leading exact zeros of b are extra delay; trailing exact zeros only lower the degree.
    nz = np.flatnonzero(b != 0.0)
    lead = int(nz[0])
    b = b[nz[0]:nz[-1] + 1]
    zeros = np.roots(b) if b.size > 1 else np.zeros(0, complex)
    radius = np.abs(zeros)
    on_circle = np.abs(radius - 1.0) < _UNIT_CIRCLE_TOL
    if np.any(on_circle):
        z = zeros[on_circle][0]
        f = abs(np.angle(z)) / (2 * np.pi * dt)
        raise ParameterError(
            f"model has a zero on the unit circle (|z|={abs(z):.12g}, {f:.4g} Hz): "
            "it can be neither inverted nor mirrored"
        )
    if method == "zmetc":
        good = radius < 1.0
    else:
        damping = _zero_damping(zeros)
        good = (radius <= max_zero_radius) & (
            (damping >= min_zero_damping) | (radius <= fast_zero_radius)
        )
    z_s, z_u = zeros[good], zeros[~good]
    # Keep complex pairs together (np.roots returns exact conjugates for real b).
    b_s = _poly_from_roots_ascending(z_s)
    # B_u: unstable roots as (q^-1 - 1/z) (bounded for huge z), the others as (1 - z q^-1).
    out = np.abs(z_u) > 1.0
    b_u = np.polynomial.polynomial.polymul(
        _poly_from_roots_ascending(1.0 / z_u[out])[::-1], _poly_from_roots_ascending(z_u[~out])
    )
    b_u = np.atleast_1d(b_u)
    # k: least-squares fit of b = k * B_s * B_u (exact up to rounding).
    prod = np.polynomial.polynomial.polymul(b_s, b_u)
    k = float(np.dot(prod, b) / np.dot(prod, prod))
    s = b_u.size - 1

    if method == "zpetc":
        bu1 = float(np.sum(b_u))
        if abs(bu1) < 1e-8 * float(np.max(np.abs(b_u))):
            raise ParameterError(
                "ZPETC gain B_u(1) is zero: an uncancelled zero sits at z = 1; use "
                "method='zmetc' or a model without a DC zero"
            )
        # F = q^(d+s) A B_u^* / (k B_s B_u(1)^2)
        num = np.polynomial.polynomial.polymul(a, b_u[::-1]) / (k * bu1 * bu1)
        den = b_s
        extra = s
    else:
        # F = q^(d+p) A / (k B_s B_u^*), B_u^* = reversed B_u (zeros mirrored to 1/z).
        num = a / k
        den = np.polynomial.polynomial.polymul(b_s, b_u[::-1])
        extra = _allpass_advance(b_u, dt, band)
    den0 = den[0]
    num, den = num / den0, den / den0
    known_num, known_den = _check_known(known, band, cutoff, dt)
    return InverseModel(
        method=method,
        num=np.ascontiguousarray(num, dtype=float),
        den=np.ascontiguousarray(den, dtype=float),
        preview=int(delay) + lead + int(extra),
        dt=float(dt),
        b_u=np.ascontiguousarray(b_u, dtype=float),
        extra_preview=int(extra),
        band_hz=band,
        cutoff_hz=cutoff,
        cancelled_zeros=z_s,
        uncancelled_zeros=z_u,
        poles=poles,
        model_delay=int(delay) + lead,
        known_num=known_num,
        known_den=known_den,
    )


def _check_known(known: Any, band: tuple[float, float] | None, cutoff: float | None,
                 dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Validate a known factor ``(num, den)``; normalised so that ``den[0] == 1``."""
    if known is None:
        return np.ones(1), np.ones(1)
    try:
        num, den = (np.atleast_1d(np.asarray(c, dtype=float)).ravel() for c in known)
    except (TypeError, ValueError):
        raise ParameterError(
            f"known={known!r} must be a pair (num, den) of coefficient arrays") from None
    if not (np.all(np.isfinite(num)) and np.all(np.isfinite(den))) or den[0] == 0.0 \
            or not np.any(num):
        raise ParameterError("known factor must have finite coefficients, den[0] != 0 and a "
                             "non-zero numerator")
    num, den = num / den[0], den / den[0]
    if den.size > 1 and np.max(np.abs(np.roots(den))) >= 1.0:
        raise ParameterError("known factor has an unstable pole (|z| >= 1)")
    if band is None:
        raise ParameterError("a known factor needs band_hz: its inverse is applied inside "
                             "the band limit")
    # |F| on the support of the band limit (lo/2 .. cutoff): its inverse must stay bounded.
    lo, _ = band
    f = np.linspace(0.5 * lo, cutoff, 2001)[1:] if lo > 0 else np.linspace(0.0, cutoff, 2001)
    x = np.exp(-2j * np.pi * f * dt)
    mag = np.abs(_eval_ascending(num, x) / _eval_ascending(den, x))
    if not np.min(mag) > 1e-3 * np.max(mag):
        i = int(np.argmin(mag))
        raise ParameterError(
            f"known factor nearly vanishes at {f[i]:.4g} Hz inside the band limit "
            f"(|F| = {mag[i]:.3g}); raise the band's low edge so that its inverse stays "
            "bounded"
        )
    return np.ascontiguousarray(num), np.ascontiguousarray(den)


def _allpass_advance(b_u: np.ndarray, dt: float, band: tuple[float, float] | None) -> int:
    """Integer advance that best removes the linear phase of ``B_u / B_u^*``."""
    if b_u.size == 1:
        return 0
    if band is None:
        f = np.linspace(0.0, 0.02, 9)[1:] / dt  # near DC: the DC group delay
    else:
        f = np.linspace(max(band[0], 1e-3 * band[1]), band[1], 64)
    w = 2 * np.pi * f * dt
    x = np.exp(-1j * w)
    phi = np.unwrap(np.angle(_eval_ascending(b_u, x) / _eval_ascending(b_u[::-1], x)))
    # least squares: phi + w p ≈ 0
    p = -float(np.dot(phi, w) / np.dot(w, w))
    return max(0, int(round(p)))


def design_inverse(model: Any, *, method: str = "zpetc",
                   band_hz: tuple[float, float] | None = None,
                   cutoff_hz: float | None = None, **options: Any) -> InverseModel:
    """Design the inverse of an identified closed-loop model (an ``ArmaxModel``).

    Only the deterministic part ``q^-delay B/A`` is used; ``model`` needs the attributes
    ``b``, ``a``, ``delay`` and ``dt``. Options are those of :func:`design_inverse_tf`.

    A model built by :func:`ehss.identification.known.compose` (identified behind known
    factors, ``meta["known_factors"]`` set) is split back into the identified rest and
    the known factor unless ``known`` is given: ``b`` and ``a`` are divided exactly by
    the factor's numerator and denominator, and the inverse is ``rest^-1 ∘ F^-1`` (the
    factor's zeros at ``z ≈ 1`` could be neither cancelled nor mirrored).

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> m = SimpleNamespace(a=[1.0, -0.5], b=[0.5], delay=1, dt=1e-3)
    >>> inv = design_inverse(m)
    >>> inv.preview, inv.num.tolist(), inv.den.tolist()
    (1, [2.0, -1.0], [1.0])
    """
    for name in ("b", "a", "delay", "dt"):
        if not hasattr(model, name):
            raise TypeError(f"model must have attributes b, a, delay, dt (missing {name!r})")
    b, a = model.b, model.a
    stored = (getattr(model, "meta", None) or {}).get("known_factors")
    if options.get("known") is None and stored is not None:
        known = (np.asarray(stored["num"], dtype=float), np.asarray(stored["den"], dtype=float))
        b = _divide_exactly(np.asarray(b, dtype=float), known[0], "b", "numerator")
        a = _divide_exactly(np.asarray(a, dtype=float), known[1], "a", "denominator")
        options["known"] = known
    return design_inverse_tf(b, a, delay=model.delay, dt=model.dt, method=method,
                             band_hz=band_hz, cutoff_hz=cutoff_hz, **options)


def _divide_exactly(p: np.ndarray, d: np.ndarray, name: str, what: str) -> np.ndarray:
    """Quotient of ``p`` by ``d`` (coefficient sequences), checking the remainder."""
    if d.size > p.size or d[0] == 0.0:
        raise ParameterError(f"model {name} is not a multiple of the known factor's {what}")
    q, rem = scipy.signal.deconvolve(p, d)
    if np.max(np.abs(rem)) > 1e-8 * max(np.max(np.abs(p)), 1e-300):
        raise ParameterError(f"model {name} is not a multiple of the known factor's {what} "
                             "(meta['known_factors'] does not belong to this model)")
    return q
