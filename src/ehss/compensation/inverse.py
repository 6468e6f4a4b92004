"""Inverse-model feed-forward design: exact stable inversion, ZPETC and ZMETC, band-limited.

An identified closed loop (reference → measured output) is the ARMAX deterministic part

.. math:: G(q^{-1}) = q^{-d}\\,\\frac{B(q^{-1})}{A(q^{-1})}

of eq (16) of the paper. Its inverse is what the identification is for: a drive
``u = G^{-1} r`` makes the loop output follow the reference ``r``. Two things stop a naive
inversion: the delay ``q^{-d}`` (inverting it needs future samples) and zeros of ``B``
outside or near the unit circle (their inverse is unstable or rings). Because the whole
drive file is known in advance, the delay is inverted exactly by *preview* (a non-causal
advance), and the bad zeros are handled by one of three designs:

* **Stable inversion** (the default; Devasia, Chen & Paden 1996 in discrete time). Factor
  ``B = k B_i B_o B_n``: zeros inside the unit circle ``B_i``, outside ``B_o`` (degree
  ``s``), and near it ``B_n`` (``| |z| - 1 | < circle_margin``). The inverse is *exact*,

  .. math:: F(q) = q^{d+s}\\,\\frac{A(q^{-1})}{k\\,B_i(q^{-1})\\,B_n(q^{-1})\\,D(q)},
            \\qquad B_o(q^{-1}) = q^{-s} D(q),

  with ``1/B_i`` run causally (forwards) and ``1/D(q)``, whose poles ``1/z`` lie inside the
  unit circle in ``q``, run anti-causally (backwards over the record): ``G F = 1`` at every
  frequency. A zero near the unit circle gives an inverse mode that decays too slowly for
  a recursive filter to settle over a record (a time constant ``1/|ln|z||`` of more than
  ``1/circle_margin`` samples), and oversampled identified models have them; ``1/B_n`` is
  therefore applied in the frequency domain together with the band limit, exactly where
  the band limit is non-zero and not at all where it is zero, so such a zero outside the
  band cannot blow up the drive. A zero on the circle inside the band cannot be inverted
  (the model says the loop does not pass that frequency): the design stops.
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

**Which one.** For a drive file (the whole reference known in advance) stable inversion is
the better choice: it is exact inside the band whatever the zeros, where ZPETC leaves the
magnitude error ``|B_u|^2/B_u(1)^2`` (which explodes when ``B_u(1)`` is small, as for the
sampling zeros of an oversampled loop with zeros near ``z = 1``) and ZMETC a phase error.
ZPETC and ZMETC remain the choice when only a short preview is available (real-time
tracking of a reference known a few samples ahead): both are causal up to a fixed advance
``d + s``, while the anti-causal part of stable inversion needs the reference until its
settling time after each sample. ZPETC suits loops whose uncancelled zeros sit near
``z = -1`` (its gain error stays out of band); ZMETC suits phase-tolerant, magnitude-
critical tests.

Every recursive filter starts in the steady state of the padded record's first sample
(backwards: its last), so a reference that does not start at rest gives no start-up spike
in the drive; the rig itself does start at rest, and :func:`ehss.compensation.compensate`
checks that the reference does too.

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
from typing import Any

import numpy as np
import scipy.fft
import scipy.signal

from ehss._checks import check_band, check_int, check_real
from ehss.compensation.inverse_model import (
    InverseModel,
    _eval_ascending,
    band_taper,
    zmetc_phase,
    zpetc_magnitude,
)
from ehss.errors import ParameterError
from ehss.identification.model import ArmaxModel

__all__ = [
    "CIRCLE_MARGIN",
    "InverseModel",
    "METHODS",
    "design_inverse",
    "design_inverse_tf",
    "band_taper",
    "zpetc_magnitude",
    "zmetc_phase",
]

METHODS = ("stable", "zpetc", "zmetc")

#: Zeros closer than this to the unit circle cannot be inverted nor mirrored.
_UNIT_CIRCLE_TOL = 1e-9

#: Default ``circle_margin`` of stable inversion: zeros with ``| |z| - 1 |`` below it
#: (an inverse mode slower than 1000 samples) are inverted in the frequency domain.
CIRCLE_MARGIN = 1e-3

#: Recursive inverse filters get 20 time constants of lead-in (their start-up transient
#: falls by e^-20 ≈ 2e-9).
_SETTLE_TIME_CONSTANTS = 20.0


# --------------------------------------------------------------------------- helpers
def _poly_from_roots_ascending(roots: np.ndarray) -> np.ndarray:
    """Coefficients ``[1, c1, .., cm]`` of ``prod(1 - r q^-1)`` in ascending powers of q^-1."""
    if roots.size == 0:
        return np.ones(1)
    c = np.poly(roots)
    return np.ascontiguousarray(np.real_if_close(c, tol=1e6).real, dtype=float)


def _zero_damping(z: np.ndarray, ) -> np.ndarray:
    """Damping ratio of the continuous mode ``s = ln z / dt`` of each zero (dt cancels)."""
    s = np.log(z.astype(complex))
    mag = np.abs(s)
    with np.errstate(invalid="ignore", divide="ignore"):
        zeta = np.where(mag > 0, -s.real / np.where(mag > 0, mag, 1.0), 1.0)
    return zeta


def _band_and_cutoff(band_hz: Any, cutoff_hz: float | None, fs: float
                     ) -> tuple[tuple[float, float] | None, float | None]:
    """The band limit's pass band (below fs/2, leaving room for the taper) and the
    frequency where its taper reaches zero (default ``min(1.5 hi, (hi + fs/2)/2)``)."""
    if band_hz is None:
        if cutoff_hz is not None:
            raise ParameterError("cutoff_hz needs band_hz")
        return None, None
    lo, hi = check_band(band_hz, "band_hz", fs=fs, below_nyquist=True)
    nyq = 0.5 * fs
    if cutoff_hz is None:
        cutoff_hz = min(1.5 * hi, hi + 0.5 * (nyq - hi))
    return (lo, hi), check_real(cutoff_hz, "cutoff_hz", lo=hi, hi=nyq, lo_open=True,
                                unit="Hz")


def _coefficients(b: Any, a: Any) -> tuple[np.ndarray, np.ndarray]:
    """``b`` and ``a`` as finite float arrays, ``a`` normalised to ``a0 = 1``; refused when
    ``b`` is all zero (no input path to invert)."""
    try:
        b = np.atleast_1d(np.asarray(b, dtype=float)).ravel()
        a = np.atleast_1d(np.asarray(a, dtype=float)).ravel()
    except (TypeError, ValueError) as exc:
        raise ParameterError(f"model coefficients must be numbers: {exc}") from None
    if not (np.all(np.isfinite(b)) and np.all(np.isfinite(a))):
        raise ParameterError("model coefficients must be finite (got NaN or inf in a or b)")
    if a.size == 0 or a[0] == 0.0:
        raise ParameterError(f"model a={a.tolist()!r} must start with a non-zero a0 (normally 1)")
    if not (b.size and np.max(np.abs(b)) > 0.0):
        raise ParameterError("model b is all zero: the model has no input path to invert")
    return b, a / a[0]


def _stable_poles(a: np.ndarray) -> np.ndarray:
    """The roots of ``A``, refused unless all are inside the unit circle: A(q^-1) goes
    into the numerator of the inverse, but an unstable model means the identification
    failed and its inverse is meaningless."""
    poles = np.roots(a) if a.size > 1 else np.zeros(0, complex)
    if poles.size:
        rmax = float(np.max(np.abs(poles)))
        if rmax >= 1.0:
            raise ParameterError(
                f"model is unstable: max pole radius {rmax:.6g} >= 1; an unstable closed-loop "
                "model cannot be inverted (re-identify it, e.g. with more data or a lower order)"
            )
    return poles


def design_inverse_tf(
    b: Any,
    a: Any,
    *,
    delay: int,
    dt: float,
    method: str = "stable",
    band_hz: tuple[float, float] | None = None,
    cutoff_hz: float | None = None,
    circle_margin: float = CIRCLE_MARGIN,
    max_zero_radius: float = 0.999,
    min_zero_damping: float = 0.1,
    fast_zero_radius: float = 0.5,
    known: tuple[Any, Any] | None = None,
) -> InverseModel:
    """Design the inverse of ``G = q^-delay B(q^-1)/A(q^-1)`` (stable, ZPETC or ZMETC).

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
    method : {"stable", "zpetc", "zmetc"}
        How the zeros outside the unit circle are handled (see the module notes).
    band_hz : (lo, hi), optional
        Pass band of the zero-phase band limit (Hz); ``None`` for none.
    cutoff_hz : float, optional
        Where the high-side taper reaches zero; default ``min(1.5 hi, (hi + fs/2)/2)``.
    circle_margin : float
        Stable inversion: zeros with ``| |z| - 1 | < circle_margin`` are inverted in the
        frequency domain inside the band limit (see the module notes).
    max_zero_radius : float
        ZPETC: zeros with ``|z|`` above this are never cancelled exactly.
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
    check_real(circle_margin, "circle_margin", lo=0.0, hi=0.5, lo_open=True, hi_open=True)
    b, a = _coefficients(b, a)
    dt = check_real(dt, "model dt", lo=0.0, lo_open=True, unit="s")
    delay = check_int(delay, "model delay", lo=0)
    band, cutoff = _band_and_cutoff(band_hz, cutoff_hz, 1.0 / dt)
    poles = _stable_poles(a)

    # Leading exact zeros of b are extra delay; trailing exact zeros only lower the degree.
    nz = np.flatnonzero(b != 0.0)
    lead = int(nz[0])
    b = b[nz[0]:nz[-1] + 1]
    zeros = np.roots(b) if b.size > 1 else np.zeros(0, complex)
    radius = np.abs(zeros)
    on_circle = np.abs(radius - 1.0) < _UNIT_CIRCLE_TOL
    if method == "stable":
        return _design_stable(b, a, zeros, poles, delay=int(delay) + lead, dt=float(dt),
                              band=band, cutoff=cutoff, circle_margin=float(circle_margin),
                              known=known)
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
    b_u = _outside_factor(z_u)
    k = _fit_gain(b, b_s, b_u)
    s = b_u.size - 1

    if method == "zpetc":
        bu1 = float(np.sum(b_u))
        if abs(bu1) < 1e-8 * float(np.max(np.abs(b_u))):
            raise ParameterError(
                "ZPETC gain B_u(1) is zero: an uncancelled zero sits at z = 1; use "
                "method='stable' or a model without a DC zero"
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
        settle_samples=_settle_samples(den),
    )


def _outside_factor(z: np.ndarray) -> np.ndarray:
    """``prod (q^-1 - 1/z)`` for ``|z| > 1`` times ``prod (1 - z q^-1)`` for the others.

    Ascending powers of q^-1; the unstable roots are written as ``(q^-1 - 1/z)`` so that
    the polynomial stays bounded for huge ``z`` (a tiny leading ``b0``).
    """
    out = np.abs(z) > 1.0
    return np.atleast_1d(np.polynomial.polynomial.polymul(
        _poly_from_roots_ascending(1.0 / z[out])[::-1], _poly_from_roots_ascending(z[~out])
    ))


def _fit_gain(b: np.ndarray, *factors: np.ndarray) -> float:
    """``k`` of ``b = k * prod(factors)``: least squares, exact up to rounding."""
    prod = np.ones(1)
    for f in factors:
        prod = np.polynomial.polynomial.polymul(prod, f)
    return float(np.dot(prod, b) / np.dot(prod, prod))


def _settle_samples(*polys_in_shift: np.ndarray) -> int:
    """Lead-in for recursive filters ``1/p``: 20 time constants of their slowest mode.

    Each ``p`` is monic ``[1, c1, .., cm]`` in the shift it runs in (q^-1 forwards, q
    backwards), with modes of radius below 1.
    """
    slowest = 0.0
    for p in polys_in_shift:
        if p.size > 1:
            # [1, c1, .., cm] with the recursion v(k) = x(k) - c1 v(k-1) - ...: modes are
            # the roots of z^m + c1 z^(m-1) + ... + cm.
            rmax = float(np.max(np.abs(np.roots(p))))
            if rmax > 0.0:
                slowest = max(slowest, 1.0 / max(-math.log(min(rmax, 1.0 - 1e-15)), 1e-15))
    return int(math.ceil(_SETTLE_TIME_CONSTANTS * slowest))


def _design_stable(b: np.ndarray, a: np.ndarray, zeros: np.ndarray, poles: np.ndarray, *,
                   delay: int, dt: float, band: tuple[float, float] | None,
                   cutoff: float | None, circle_margin: float, known: Any) -> InverseModel:
    """Exact stable inverse ``q^(d+s) A / (k B_i B_n D(q))`` (see the module notes)."""
    radius = np.abs(zeros)
    near = np.abs(radius - 1.0) < circle_margin
    z_in = zeros[(radius < 1.0) & ~near]
    z_out = zeros[(radius > 1.0) & ~near]
    z_near = zeros[near]
    b_in = _poly_from_roots_ascending(z_in)
    # B_o(q^-1) = prod (q^-1 - 1/z) = q^-s prod(1 - q/z) = q^-s D(q)
    b_out = _outside_factor(z_out)
    anti_den = _poly_from_roots_ascending(1.0 / z_out)  # D(q), ascending powers of q
    b_near = _poly_from_roots_ascending(z_near)
    k = _fit_gain(b, b_in, b_out, b_near)
    known_num, known_den = _check_known(known, band, cutoff, dt)
    if z_near.size:
        _check_near_zeros(z_near, band, cutoff, dt)
    s = int(z_out.size)
    return InverseModel(
        method="stable",
        num=np.ascontiguousarray(a / k, dtype=float),
        den=np.ascontiguousarray(b_in, dtype=float),
        anti_den=np.ascontiguousarray(anti_den, dtype=float),
        near_b=np.ascontiguousarray(b_near, dtype=float),
        preview=delay + s,
        dt=dt,
        b_u=np.ascontiguousarray(b_out, dtype=float),
        extra_preview=s,
        band_hz=band,
        cutoff_hz=cutoff,
        cancelled_zeros=np.concatenate([z_in, z_out]),
        near_zeros=z_near,
        poles=poles,
        model_delay=delay,
        known_num=known_num,
        known_den=known_den,
        settle_samples=_settle_samples(b_in, anti_den),
    )


def _check_near_zeros(z_near: np.ndarray, band: tuple[float, float] | None,
                      cutoff: float | None, dt: float) -> None:
    """A zero (almost) on the unit circle where the band limit passes cannot be inverted."""
    f_zero = np.abs(np.angle(z_near)) / (2.0 * np.pi * dt)
    weight = band_taper(f_zero, band, cutoff)
    bad = (np.abs(np.abs(z_near) - 1.0) < _UNIT_CIRCLE_TOL) & (weight > 0.0)
    if np.any(bad):
        z = z_near[bad][0]
        f = abs(np.angle(z)) / (2 * np.pi * dt)
        where = "no band limit" if band is None else f"band limit {band[0]:g}-{cutoff:g} Hz"
        raise ParameterError(
            f"model has a zero on the unit circle (|z|={abs(z):.12g}, {f:.4g} Hz) inside the "
            f"{where}: the model says the loop does not pass {f:.4g} Hz and cannot be "
            "inverted there; narrow the band or re-identify"
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
    if band is None or cutoff is None:
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


def design_inverse(model: ArmaxModel, *, method: str = "stable",
                   band_hz: tuple[float, float] | None = None,
                   cutoff_hz: float | None = None,
                   circle_margin: float = CIRCLE_MARGIN,
                   known: tuple[Any, Any] | None = None) -> InverseModel:
    """Design the inverse of an identified closed-loop model.

    Only the deterministic part ``q^-delay B/A`` is used. The band limit is ``band_hz``,
    or by default the band the model was validated over (``model.band_hz``); a model
    without one is inverted without a band limit (:func:`ehss.compensation.compensate`
    insists on a band). Other options are those of :func:`design_inverse_tf`.

    A model built by :func:`ehss.identification.known.compose` (identified behind known
    factors, ``meta["known_factors"]`` set) is split back into the identified rest and
    the known factor unless ``known`` is given: ``b`` and ``a`` are divided exactly by
    the factor's numerator and denominator, and the inverse is ``rest^-1 ∘ F^-1`` (the
    factor's zeros at ``z ≈ 1`` could be neither cancelled nor mirrored).

    Raises
    ------
    TypeError
        ``model`` is not an :class:`~ehss.identification.model.ArmaxModel`.
    ParameterError
        See :func:`design_inverse_tf`.

    Examples
    --------
    >>> from ehss.identification.model import ArmaxModel
    >>> m = ArmaxModel(a=[1.0, -0.5], b=[0.5], delay=1, dt=1e-3)
    >>> inv = design_inverse(m)
    >>> inv.preview, inv.num.tolist(), inv.den.tolist()
    (1, [2.0, -1.0], [1.0])
    """
    if not isinstance(model, ArmaxModel):
        raise TypeError(f"model must be an ArmaxModel, not {type(model).__name__}")
    b, a = model.b, model.a
    stored = model.meta.get("known_factors")
    if known is None and stored is not None:
        known = (np.asarray(stored["num"], dtype=float), np.asarray(stored["den"], dtype=float))
        b = _divide_exactly(np.asarray(b, dtype=float), known[0], "b", "numerator")
        a = _divide_exactly(np.asarray(a, dtype=float), known[1], "a", "denominator")
    band = model.band_hz if band_hz is None else band_hz
    return design_inverse_tf(b, a, delay=model.delay, dt=model.dt, method=method,
                             band_hz=band, cutoff_hz=cutoff_hz, circle_margin=circle_margin,
                             known=known)


def _divide_exactly(p: np.ndarray, d: np.ndarray, name: str, what: str) -> np.ndarray:
    """Quotient of ``p`` by ``d`` (coefficient sequences), checking the remainder."""
    if d.size > p.size or d[0] == 0.0:
        raise ParameterError(f"model {name} is not a multiple of the known factor's {what}")
    q, rem = scipy.signal.deconvolve(p, d)
    if np.max(np.abs(rem)) > 1e-8 * max(np.max(np.abs(p)), 1e-300):
        raise ParameterError(f"model {name} is not a multiple of the known factor's {what} "
                             "(meta['known_factors'] does not belong to this model)")
    return q
