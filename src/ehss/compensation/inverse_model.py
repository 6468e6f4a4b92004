"""A designed inverse of a closed-loop model, and how it is applied to a reference.

:class:`InverseModel` holds the result of :func:`ehss.compensation.inverse.design_inverse`:
a causal filter ``num/den`` run forwards, an anti-causal filter ``1/D(q)`` run backwards,
an advance (preview), and a frequency-domain stage (the band limit, divided by the known
factor and by the zeros near the unit circle). The band limit is a zero-phase raised-cosine
taper applied by FFT over a padded record (:func:`band_taper`). The analytic overall
responses of ZPETC and ZMETC are here too (:func:`zpetc_magnitude`, :func:`zmetc_phase`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.fft
import scipy.signal

from ehss._checks import as_signal, check_int
from ehss.errors import ParameterError

__all__ = ["InverseModel", "band_taper", "zpetc_magnitude", "zmetc_phase"]


def _eval_ascending(coef: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Evaluate ``sum coef[i] x**i`` (``x = e^{-jωdt}`` gives a polynomial in q^-1)."""
    return np.polynomial.polynomial.polyval(x, coef)



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
    """A designed feed-forward inverse of a closed-loop model.

    The drive is ``u(k) = v(k + preview)`` with ``v = D(q)^-1 [num/den] r_band``: ``r_band``
    the band-limited reference (divided, inside the band limit, by the near-circle factor
    and the known factor), ``num/den`` run forwards and ``1/D(q)`` backwards.

    Attributes
    ----------
    method : {"stable", "zpetc", "zmetc"}
    num, den : ndarray
        Causal filter in ascending powers of q^-1 (``den[0] == 1``).
    anti_den : ndarray
        ``D(q)`` in ascending powers of q (``[1.]`` but for stable inversion of a model
        with zeros outside the unit circle), run anti-causally.
    near_b : ndarray
        ``B_n(q^-1)``, the zeros near the unit circle inverted in the frequency domain
        (``[1.]`` if none).
    preview : int
        Samples of advance (non-causal part): model delay + leading zero b's + ``s``
        (stable inversion, ZPETC) or + the all-pass advance (ZMETC).
    dt : float
        Sample period (s).
    b_u : ndarray
        ZPETC/ZMETC: the uncancelled factor ``B_u``; stable inversion: ``B_o``
        (ascending powers of q^-1, ``[1.]`` if none).
    extra_preview : int
        Advance beyond the model delay.
    band_hz : (float, float) or None
        Pass band ``(lo, hi)`` of the band limit; ``None`` for no band limit.
    cutoff_hz : float or None
        Above this frequency the band limit is exactly zero.
    cancelled_zeros, uncancelled_zeros, near_zeros, poles : ndarray
        Zeros inverted by a recursive filter (forwards, and for stable inversion
        backwards too), zeros handled by the ZPETC/ZMETC factor, zeros inverted in the
        frequency domain, model poles.
    model_delay : int
        Total model delay (``delay`` plus leading zero b's).
    known_num, known_den : ndarray
        Known factor ``F = N/D`` in series with the inverted model (ascending powers of
        q^-1; ``[1.]`` and ``[1.]`` for none). Its inverse is applied in the frequency
        domain with the band limit (see the module notes).
    settle_samples : int
        Lead-in the recursive filters need to forget their start (20 time constants of
        their slowest mode).
    """

    method: str
    num: np.ndarray
    den: np.ndarray
    preview: int
    dt: float
    b_u: np.ndarray
    extra_preview: int
    anti_den: np.ndarray = field(default_factory=lambda: np.ones(1))
    near_b: np.ndarray = field(default_factory=lambda: np.ones(1))
    band_hz: tuple[float, float] | None = None
    cutoff_hz: float | None = None
    cancelled_zeros: np.ndarray = field(default_factory=lambda: np.zeros(0, complex))
    uncancelled_zeros: np.ndarray = field(default_factory=lambda: np.zeros(0, complex))
    near_zeros: np.ndarray = field(default_factory=lambda: np.zeros(0, complex))
    poles: np.ndarray = field(default_factory=lambda: np.zeros(0, complex))
    model_delay: int = 0
    known_num: np.ndarray = field(default_factory=lambda: np.ones(1))
    known_den: np.ndarray = field(default_factory=lambda: np.ones(1))
    settle_samples: int = 0

    @property
    def has_known(self) -> bool:
        """Whether a known factor ``F`` other than 1 is inverted too."""
        return not (self.known_num.size == 1 and self.known_den.size == 1
                    and self.known_num[0] == self.known_den[0])

    def known_response(self, freq_hz: np.ndarray) -> np.ndarray:
        """Complex response of the known factor ``F = N/D`` at ``freq_hz``."""
        x = np.exp(-2j * np.pi * np.asarray(freq_hz, dtype=float) * self.dt)
        return _eval_ascending(self.known_num, x) / _eval_ascending(self.known_den, x)

    def _spectral_response(self, freq_hz: np.ndarray) -> np.ndarray:
        """Known factor times near-circle factor: what the frequency-domain stage divides."""
        x = np.exp(-2j * np.pi * np.asarray(freq_hz, dtype=float) * self.dt)
        return self.known_response(freq_hz) * _eval_ascending(self.near_b, x)

    @property
    def _needs_spectral_stage(self) -> bool:
        return self.has_known or self.near_b.size > 1

    @property
    def fs(self) -> float:
        """Sample rate (Hz)."""
        return 1.0 / self.dt

    # ---------------------------------------------------------------- responses
    def band_response(self, freq_hz: np.ndarray) -> np.ndarray:
        """Real gain of the band limit at ``freq_hz``."""
        return band_taper(freq_hz, self.band_hz, self.cutoff_hz)

    def frequency_response(self, freq_hz: np.ndarray, *, band: bool = True) -> np.ndarray:
        """Complex response of the inverse ``F`` (× the band limit).

        Parameters
        ----------
        freq_hz : array_like
            Frequencies (Hz).
        band : bool
            Include the band limit (default); the inverse is then zero wherever the band
            limit is.
        """
        f = np.asarray(freq_hz, dtype=float)
        w = 2.0 * np.pi * f * self.dt
        x = np.exp(-1j * w)
        h = _eval_ascending(self.num, x) / _eval_ascending(self.den, x)
        # 1/D(q) with q = e^{jω}: the anti-causal part
        h = h / _eval_ascending(self.anti_den, 1.0 / x)
        h = h * np.exp(1j * w * self.preview)
        if self._needs_spectral_stage:
            with np.errstate(divide="ignore", invalid="ignore"):
                h = h / self._spectral_response(f)
        if band:
            wgt = self.band_response(f)
            h = h * wgt
            if self._needs_spectral_stage:
                h = np.where(wgt > 0.0, h, 0.0)
        return h

    def design_response(self, freq_hz: np.ndarray) -> np.ndarray:
        """Analytic overall response ``G·F`` the design aims at (no band limit).

        A known factor is cancelled exactly and does not appear here. Stable inversion:
        1; ZPETC: ``|B_u|^2 / B_u(1)^2`` (real, non-negative); ZMETC: ``e^{jφ}`` with φ
        from :func:`zmetc_phase`.
        """
        f = np.asarray(freq_hz, dtype=float)
        if self.method == "stable":
            return np.ones(f.shape, complex)
        if self.method == "zpetc":
            return zpetc_magnitude(self.b_u, f, self.dt).astype(complex)
        return np.exp(1j * zmetc_phase(self.b_u, self.extra_preview, f, self.dt))

    # ---------------------------------------------------------------- apply
    def apply(self, reference: Any, *, preview: int | None = None) -> np.ndarray:
        """Drive that makes the modelled loop follow ``reference``.

        Parameters
        ----------
        reference : array_like, shape (n_samples,)
            Reference sampled at ``1/dt``. Before its start it is taken as held at its
            first value, after its end at its last (the filters start in steady state).
        preview : int, optional
            Future reference samples the compensator may use (ZPETC and ZMETC only).
            ``None`` (default) means the whole file is known and the full designed preview
            is used. With less preview the drive is causal up to that advance and the
            tracking lags by the difference.

        Returns
        -------
        drive : ndarray, shape (n_samples,)
            At the model's rate ``1/dt``, as the reference.

        Raises
        ------
        DataError
            Empty, non-1-D or non-finite reference.
        ParameterError
            Negative ``preview``, or a reduced preview for stable inversion (its
            anti-causal part needs the whole reference).
        """
        r = as_signal(reference, "reference")
        advance = self.preview
        if preview is not None:
            preview = check_int(preview, "preview", lo=0)
            if self.method == "stable" and preview < self.preview:
                raise ParameterError(
                    f"preview={preview} is below the stable inverse's {self.preview} samples: "
                    "its anti-causal part needs the whole reference (use method='zpetc' or "
                    "'zmetc' for a limited preview)")
            advance = min(int(preview), self.preview)
        if self.band_hz is not None or self._needs_spectral_stage:
            shape = None
            if self._needs_spectral_stage:
                def shape(f: np.ndarray) -> np.ndarray:
                    w = band_taper(f, self.band_hz, self.cutoff_hz)
                    with np.errstate(divide="ignore", invalid="ignore"):
                        return np.where(w > 0.0, w / self._spectral_response(f), 0.0)
            # The band limit is non-causal: the limited reference rings a little before
            # the record starts and after it ends. The filters run over that lead-in and
            # tail, and the preview reads the limited continuation.
            x, npad = _fft_band_limit(r, self.dt, self.band_hz, self.cutoff_hz, shape,
                                      padded=True, min_pad=self.settle_samples + advance)
        else:
            # r held at its first value before the start and its last after the end
            npad = self.settle_samples + 1
            x = np.concatenate([np.full(npad, r[0]), r, np.full(npad + advance, r[-1])])
        v = _run_filters(self.num, self.den, self.anti_den, x)
        # u(k) = v(k + preview): the non-causal advance that inverts q^-d (and q^-s).
        return np.ascontiguousarray(v[npad + advance: npad + advance + r.size])


def _steady_lfilter(b: np.ndarray, a: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``lfilter(b, a, x)`` started in the steady state of a constant input ``x[0]``."""
    if max(b.size, a.size) == 1:
        return x * (b[0] / a[0])
    zi = scipy.signal.lfilter_zi(b, a) * x[0]
    return scipy.signal.lfilter(b, a, x, zi=zi)[0]


def _run_filters(num: np.ndarray, den: np.ndarray, anti_den: np.ndarray,
                 x: np.ndarray) -> np.ndarray:
    """``D(q)^-1 [num/den](q^-1) x``: the causal part forwards, then ``1/D`` backwards."""
    v = _steady_lfilter(num, den, x)
    if anti_den.size > 1:
        # D(q) v2 = v  <=>  sum_j D_j v2(k + j) = v(k): a causal recursion on the
        # time-reversed signal, stable because D's roots in q lie outside the unit circle.
        v = _steady_lfilter(np.ones(1), anti_den, v[::-1])[::-1]
    return v


def _fft_band_limit(r: np.ndarray, dt: float, band_hz: tuple[float, float] | None,
                    cutoff_hz: float | None, shape: Any = None, *, padded: bool = False,
                    min_pad: int = 0) -> Any:
    """Zero-phase band limit by FFT with constant-extended padding (no wrap-around).

    ``shape(freq_hz) -> complex`` replaces the band taper when given (band limit times
    the inverse of a known factor and of the near-circle zeros); it must vanish wherever
    the taper does. With ``padded=True`` returns ``(y, npad)``: the limited signal with
    ``npad >= min_pad`` samples of lead-in before the record and at least ``npad`` after
    it.
    """
    if band_hz is None:
        width = 1.0 / (r.size * dt)
    else:
        lo, hi = band_hz
        widths = [w for w in ((cutoff_hz - hi) if cutoff_hz else 0.0, 0.5 * lo) if w > 0]
        width = min(widths) if widths else 1.0 / (r.size * dt)
    # The taper's impulse response decays within a few 1/width: pad by 8/width each side.
    npad = int(min(max(math.ceil(8.0 / (width * dt)), 16), 4 * r.size + 16))
    npad = max(npad, int(min_pad))
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
