"""Inverse-model design: exact (stable) inversion, ZPETC/ZMETC analytic responses, band
limit, errors."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal
from numpy.polynomial import polynomial as P
from numpy.testing import assert_allclose

from ehss.compensation import (
    compensate,
    design_inverse,
    design_inverse_tf,
    zmetc_phase,
    zpetc_magnitude,
)
from ehss.errors import DataError, EhssWarning, ParameterError
from ehss.identification.model import ArmaxModel
from ehss.signals import Signal

DT = 1e-3
FREQ = np.linspace(0.0, 499.0, 400)


def _model(b, a, delay, dt=DT, **kw):
    return ArmaxModel(b=np.asarray(b, float), a=np.asarray(a, float), c=[1.0], delay=delay,
                      dt=dt, **kw)


def _simulate(model, u):
    """Noise-free q^-d B/A with zero initial conditions (slow, obvious reference)."""
    return scipy.signal.lfilter(np.r_[np.zeros(model.delay), model.b], model.a, u)


def _response(model, f):
    x = np.exp(-2j * np.pi * f * model.dt)
    return x**model.delay * P.polyval(x, model.b) / P.polyval(x, model.a)


def _at_rest_reference(rng, n=2000, lead=50):
    r = scipy.signal.lfilter([0.05], [1, -0.95], rng.standard_normal(n))
    r[:lead] = 0.0
    return r


@pytest.fixture
def min_phase():
    a = np.real(np.poly([0.95, 0.8 + 0.3j, 0.8 - 0.3j]))
    b = 0.02 * np.poly([0.3, -0.4])
    return _model(b, a, delay=2)


@pytest.fixture
def non_min_phase():
    a = np.real(np.poly([0.9, 0.7 + 0.4j, 0.7 - 0.4j, 0.2]))
    # An unstable sampling zero at -3.7, a slow unstable zero at 1.3, a stable one at 0.5.
    b = 0.01 * np.poly([-3.7, 1.3, 0.5])
    return _model(b, a, delay=1)


def test_min_phase_inverse_is_identity_with_preview(min_phase, rng):
    r = _at_rest_reference(rng)
    for method in ("stable", "zpetc", "zmetc"):
        inv = design_inverse(min_phase, method=method)
        assert inv.preview == min_phase.delay
        y = _simulate(min_phase, inv.apply(r))
        # Exact cancellation: only rounding of a ~2000-step recursion (|r| ~ 0.1).
        assert_allclose(y, r, rtol=0, atol=1e-10)


def test_leading_zero_b_is_extra_delay(rng):
    a = [1.0, -0.9]
    m = _model([0.0, 0.0, 0.1, 0.05], a, delay=1)
    inv = design_inverse(m)
    assert inv.preview == 3
    r = _at_rest_reference(rng)
    assert_allclose(_simulate(m, inv.apply(r)), r, rtol=0, atol=1e-10)


def test_zpetc_zero_phase_and_analytic_magnitude(non_min_phase):
    inv = design_inverse(non_min_phase, method="zpetc")
    assert inv.preview == non_min_phase.delay + 2  # two uncancelled zeros
    overall = _response(non_min_phase, FREQ) * inv.frequency_response(FREQ)
    # Phase exactly zero up to rounding of the polynomial evaluations.
    assert np.max(np.abs(np.angle(overall))) < 1e-9
    b_u = np.poly([-3.7, 1.3])  # any scaling: the ratio |B_u|^2/B_u(1)^2 does not depend on it
    expected = zpetc_magnitude(b_u, FREQ, DT)
    assert_allclose(np.abs(overall), expected, rtol=1e-9)
    assert_allclose(overall[0], 1.0, rtol=1e-12)
    assert_allclose(inv.design_response(FREQ), overall, rtol=1e-9, atol=1e-12)


def test_zpetc_time_domain_equals_zero_phase_filter(non_min_phase, rng):
    inv = design_inverse(non_min_phase, method="zpetc")
    r = np.r_[np.zeros(50), _at_rest_reference(rng), np.zeros(50)]
    y = _simulate(non_min_phase, inv.apply(r))
    # y = B_u(q^-1) B_u(q) r / B_u(1)^2, a symmetric FIR.
    b_u = np.poly([-3.7, 1.3])
    sym = np.convolve(b_u, b_u[::-1]) / np.sum(b_u) ** 2
    expected = np.convolve(r, sym)[b_u.size - 1:][: r.size]
    assert_allclose(y, expected, rtol=0, atol=1e-10)


def test_zmetc_unit_magnitude_and_analytic_phase(non_min_phase):
    inv = design_inverse(non_min_phase, method="zmetc")
    overall = _response(non_min_phase, FREQ) * inv.frequency_response(FREQ)
    assert_allclose(np.abs(overall), 1.0, rtol=1e-12)
    b_u = np.poly([-3.7, 1.3])
    phase = zmetc_phase(b_u, inv.extra_preview, FREQ, DT)
    assert np.max(np.abs(np.angle(overall * np.exp(-1j * phase)))) < 1e-9
    # The mirrored zeros make the inverse stable.
    assert np.all(np.abs(np.roots(inv.den)) < 1.0)


def test_tiny_b0_is_a_delay_not_a_blow_up(rng):
    # b0 ~ 1e-9: a zero near -1e7, handled by ZPETC as one more sample of preview.
    a = np.real(np.poly([0.9, 0.6]))
    m = _model([1e-9, 0.1, 0.05], a, delay=1)
    r = _at_rest_reference(rng)
    for method in ("stable", "zpetc", "zmetc"):
        inv = design_inverse(m, method=method)
        assert inv.preview == 2
        y = _simulate(m, inv.apply(r))
        # The residual error is of the order b0/b1 = 1e-8 times the reference (~0.2).
        assert_allclose(y[:-2], r[:-2], rtol=0, atol=1e-7)


def test_band_limit_gain_at_most_one_beyond_cutoff(non_min_phase, rng):
    inv = design_inverse(non_min_phase, band_hz=(0.0, 50.0))
    assert inv.cutoff_hz == pytest.approx(75.0)
    f = np.linspace(inv.cutoff_hz, 500.0, 500)
    assert np.all(np.abs(inv.frequency_response(f)) <= 1.0)
    # Inside the band the band limit is exactly 1.
    assert_allclose(inv.band_response(np.linspace(0, 50, 50)), 1.0, rtol=0, atol=0)
    # Time domain: white noise in, no drive content above the cutoff.
    noise = rng.standard_normal(16384)
    drive = inv.apply(noise)
    f_w, p_noise = scipy.signal.welch(noise, fs=1 / DT, nperseg=1024)
    _, p_drive = scipy.signal.welch(drive, fs=1 / DT, nperseg=1024)
    above = f_w > inv.cutoff_hz + 10.0
    # Exactly zero by design; what remains is Hann-window leakage from the pass band.
    assert np.max(p_drive[above] / p_noise[above]) < 1e-4
    unlimited = design_inverse(non_min_phase)
    assert np.max(np.abs(unlimited.frequency_response(f))) > 1.0  # the reason for the limit


def test_band_limit_low_edge():
    inv = design_inverse_tf([0.5], [1.0, -0.5], delay=1, dt=DT, band_hz=(1.0, 50.0))
    assert inv.band_response(np.array([0.0, 0.5]))[0] == 0.0
    assert_allclose(inv.band_response(np.array([1.0, 10.0])), 1.0)


def test_unstable_poles_named():
    with pytest.raises(ParameterError, match=r"max pole radius 1\.1"):
        design_inverse(_model([0.1], [1.0, -1.1], delay=1))


def test_b_all_zero():
    with pytest.raises(ParameterError, match="all zero"):
        design_inverse_tf([0.0, 0.0], [1.0, -0.5], delay=1, dt=DT)


def test_non_finite_coefficients():
    with pytest.raises(ParameterError, match="finite"):
        design_inverse_tf([np.nan], [1.0, -0.5], delay=1, dt=DT)


@pytest.mark.parametrize("method", ["stable", "zpetc", "zmetc"])
def test_zero_on_unit_circle(method):
    with pytest.raises(ParameterError, match="unit circle"):
        design_inverse(_model([1.0, -1.0], [1.0, -0.5], delay=1), method=method)


def test_model_type_is_checked():
    from types import SimpleNamespace

    with pytest.raises(TypeError, match="ArmaxModel"):
        design_inverse(SimpleNamespace(a=[1.0], b=[1.0], delay=1, dt=DT))


@pytest.mark.parametrize("bad", [[], [np.nan, 1.0], [[1.0, 2.0]], [0.0, np.inf]])
def test_bad_reference(bad):
    m = _model([0.5], [1.0, -0.5], delay=1, band_hz=(0.0, 100.0))
    with pytest.raises(DataError):
        compensate(m, np.asarray(bad, dtype=float), fs=1 / DT)


def test_sample_rate_mismatch():
    m = _model([0.5], [1.0, -0.5], delay=1, band_hz=(0.0, 100.0))
    r = np.sin(np.pi * np.arange(10) / 9) ** 2
    with pytest.raises(DataError, match="500 Hz but the model at 1000 Hz"):
        compensate(m, r, fs=500.0)
    # a model is applied at its rate or an integer multiple of it, not at any other
    with pytest.raises(DataError, match="2500 Hz but the model at 1000 Hz"):
        compensate(m, Signal(values=r, fs=2500.0, kind="test"))
    with pytest.raises(ParameterError, match="differs from the Signal"):
        compensate(m, Signal(values=r, fs=1000.0, kind="test"), fs=2000.0)
    with pytest.raises(ParameterError, match="fs must be given"):
        compensate(m, r)
    # ten samples: much of their power is beyond the model's 100 Hz band, and it says so
    with pytest.warns(EhssWarning, match="outside the band 0-100 Hz"):
        assert compensate(m, Signal(values=r, fs=1000.0, kind="test")).shape == (10,)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"method": "lqr"}, "method"),
        ({"band_hz": (10.0, 5.0)}, "band_hz"),
        ({"band_hz": (0.0, 600.0)}, "band_hz"),
    ],
)
def test_bad_design_options(kwargs, match):
    with pytest.raises(ParameterError, match=match):
        design_inverse(_model([0.5], [1.0, -0.5], delay=1), **kwargs)


def test_reduced_preview_lags():
    m = _model([0.5], [1.0, -0.5], delay=3)
    r = np.r_[np.zeros(10), np.ones(20)]
    inv = design_inverse(m, method="zpetc")
    y = _simulate(m, inv.apply(r, preview=1))
    assert_allclose(y[2:], r[:-2], atol=1e-12)  # lags by 3 - 1 samples
    with pytest.raises(ParameterError, match="preview"):
        inv.apply(r, preview=-1)
    # stable inversion runs anti-causally: it needs the whole reference
    with pytest.raises(ParameterError, match="whole reference"):
        design_inverse(m).apply(r, preview=1)


# --------------------------------------------------------------------------- known factors
def _acceleration_known():
    from ehss.control.known import known_factors
    from ehss.params import preset

    return known_factors("acceleration", preset("default"))


def test_known_factor_inverse_response_is_exact(min_phase):
    # Loop = G·F with F the acceleration loop's generator (eq 10) and accelerometer
    # coupling. The inverse times the loop is the band limit itself (G's zeros are all
    # cancelled): exact up to rounding of polynomials evaluated near their roots at
    # z ≈ 0.997 (relative 1e-7, as for compose).
    num, den = _acceleration_known()
    inv = design_inverse(min_phase, band_hz=(1.0, 50.0), known=(num, den))
    f = np.linspace(0.0, 499.0, 2000)
    _, hf = scipy.signal.freqz(num, den, worN=f, fs=1 / DT)
    overall = inv.frequency_response(f) * _response(min_phase, f) * hf
    assert_allclose(overall, inv.band_response(f), rtol=0, atol=1e-7)
    assert np.all(inv.frequency_response(f[f <= 0.5]) == 0.0)  # no 1/F growth below lo/2


def test_known_factor_drive_tracks_in_time(min_phase):
    # A reference at rest and in band (tones under a Gaussian envelope): the loop G·F
    # driven by the inverse follows it. The FFT inverse of F acts on the padded record;
    # what remains is rounding, amplified by F's poles and zeros at z ≈ 0.997 (measured
    # 1.4e-10 of the peak; 1e-8 leaves room for other FFT and BLAS builds).
    num, den = _acceleration_known()
    t = np.arange(8000) * DT
    r = (np.sin(2 * np.pi * 3.0 * t) + 0.5 * np.sin(2 * np.pi * 17.0 * t + 1.0)) * np.exp(
        -(((t - 4.0) / 0.7) ** 2))
    drive = compensate(min_phase, r, fs=1 / DT, band_hz=(1.0, 50.0), known=(num, den))
    y = scipy.signal.lfilter(num, den, _simulate(min_phase, drive))
    assert_allclose(y, r, rtol=0, atol=1e-8 * np.max(np.abs(r)))


def test_band_limited_drive_starts_without_a_jump(min_phase):
    # A reference that does not start at rest: the inverse filter runs over the band
    # limit's lead-in, so the drive does not jump at t = 0 (without the lead-in its first
    # sample would be the high-frequency gain of A/B times r_band(0): measured 25 against
    # a steady peak of 0.4).
    t = np.arange(2000) * DT
    r = np.cos(2 * np.pi * 5.0 * t)
    drive = design_inverse(min_phase, band_hz=(1.0, 50.0)).apply(r)
    steady = np.max(np.abs(drive[500:1500]))
    assert np.max(np.abs(drive[:50])) < 1.5 * steady


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"band_hz": None}, "needs band_hz"),
        ({"band_hz": (0.0, 50.0)}, "vanishes at 0 Hz"),
        ({"band_hz": (1.0, 50.0), "known": ([1.0], [1.0, -1.01])}, "unstable"),
        ({"band_hz": (1.0, 50.0), "known": ([0.0], [1.0])}, "non-zero"),
        ({"band_hz": (1.0, 50.0), "known": "F"}, "pair"),
    ],
)
def test_bad_known_factor(min_phase, kwargs, match):
    kwargs = {"known": _acceleration_known(), **kwargs}
    with pytest.raises(ParameterError, match=match):
        design_inverse(min_phase, **kwargs)


def test_composed_model_with_foreign_known_factor(min_phase):
    num, den = _acceleration_known()
    m = _model(min_phase.b, min_phase.a, delay=2,
               meta={"known_factors": {"num": num.tolist(), "den": den.tolist()}})
    with pytest.raises(ParameterError, match="not a multiple"):
        design_inverse(m, band_hz=(1.0, 50.0))
