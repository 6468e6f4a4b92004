"""Exact stable inversion: G·F = 1 in the band, near-circle zeros, steady starts, checks."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.polynomial import polynomial as P
from numpy.testing import assert_allclose

from ehss.compensation import (
    DriveLimits,
    check_at_rest,
    check_drive,
    compensate,
    design_inverse,
    fade_to_rest,
)
from ehss.errors import ParameterError
from ehss.identification.model import ArmaxModel
from ehss.params import preset

FS = 1000.0
DT = 1.0 / FS


def _model(zeros, poles, gain, delay, band=None):
    b = gain * np.real(np.poly(zeros))
    a = np.real(np.poly(poles))
    return ArmaxModel(a=a, b=b, c=[1.0], delay=delay, dt=DT, band_hz=band)


def _loop(model, u):
    """The model as a plain filter from rest: q^-d B/A (an independent reference)."""
    return scipy.signal.lfilter(np.r_[np.zeros(model.delay), model.b], model.a, u)


def _response(model, f):
    x = np.exp(-2j * np.pi * f * model.dt)
    return x**model.delay * P.polyval(x, model.b) / P.polyval(x, model.a)


def _in_band_reference(n=8000, centre_s=4.0, width_s=0.7):
    # Tones at 6-23 Hz under a Gaussian envelope: at rest to 1e-40 at both ends and, as a
    # finite record, inside 0-50 Hz to rounding (the envelope's spectrum is Gaussian and
    # ~0.2 Hz wide), so the band limit is unity on it.
    t = np.arange(n) * DT
    tones = sum(np.sin(2 * np.pi * f * t + p) for f, p in ((6, 0.3), (11, 1.0), (17, 2.0),
                                                           (23, 0.5)))
    return tones * np.exp(-(((t - centre_s) / width_s) ** 2))


@pytest.fixture
def non_min_phase():
    # A sampling zero at -3.7 and a slow zero at 1.3, both outside the unit circle, a
    # zero inside at 0.5; well-damped poles; one sample of delay.
    return _model([-3.7, 1.3, 0.5], [0.9, 0.7 + 0.4j, 0.7 - 0.4j, 0.2], 0.01, 1,
                  band=(0.0, 50.0))


def test_stable_inverse_response_is_one_in_band(non_min_phase):
    inv = design_inverse(non_min_phase)
    assert inv.method == "stable" and inv.preview == 1 + 2  # delay + two outside zeros
    f = np.linspace(0.0, 50.0, 501)
    overall = inv.frequency_response(f) * _response(non_min_phase, f)
    # Products of polynomials of degree <= 4 evaluated on the unit circle: rounding only.
    assert_allclose(overall, 1.0, rtol=0, atol=1e-12)


def test_stable_inverse_is_exact_in_time(non_min_phase):
    # G·F·r = r, checked by running the model as a causal filter on the drive. The drive
    # of the anti-causal part starts before t = 0: the reference is at rest at both ends
    # (Gaussian envelope, 1e-40), so the drive decays to rounding there (the slowest
    # anti-causal mode is 1/1.3 per sample), and the whole record can be compared.
    r = _in_band_reference()
    drive = design_inverse(non_min_phase).apply(r)
    y = _loop(non_min_phase, drive)
    # Exact inversion: what remains is rounding of the FFT band limit and of ~10^4-step
    # recursions on a signal of peak ~2 (measured ~1e-14); 1e-9 is the required accuracy.
    assert_allclose(y, r, rtol=0, atol=1e-9 * np.max(np.abs(r)))
    # ZPETC on the same plant leaves its magnitude error |B_u|^2/B_u(1)^2 - 1: far from r.
    zpetc = design_inverse(non_min_phase, method="zpetc").apply(r)
    assert np.max(np.abs(_loop(non_min_phase, zpetc) - r)) > 1e-2 * np.max(np.abs(r))


def test_stable_inverse_of_a_reference_not_at_rest_starts_in_steady_state(non_min_phase):
    # A constant reference c: the drive is c / G(1) from the first sample (the filters
    # start in the steady state of the held reference), with no start-up spike.
    c = 0.7
    drive = design_inverse(non_min_phase).apply(np.full(500, c))
    dc_gain = non_min_phase.dc_gain()
    # Rounding only: constants pass the FFT band limit exactly (DC gain 1).
    assert_allclose(drive, c / dc_gain, rtol=1e-12)


def test_near_circle_zero_outside_the_band_is_inverted_spectrally():
    # An oversampled model's zero just outside the unit circle near Nyquist (|z| = 1.0002,
    # 480 Hz): its inverse mode would take ~5000 samples per time constant and its gain
    # there is 5000. It is inverted in the frequency domain where the band limit passes,
    # so the drive is bounded and G F r = r stays exact in the band.
    z_near = 1.0002 * np.exp(1j * 2 * np.pi * 480 * DT)
    m = _model([z_near, np.conj(z_near), -3.7], [0.9, 0.6], 0.05, 1, band=(0.0, 50.0))
    inv = design_inverse(m)
    assert inv.near_zeros.size == 2 and inv.anti_den.size == 2
    r = _in_band_reference()
    drive = inv.apply(r)
    assert np.max(np.abs(drive)) < 3.0 * np.max(np.abs(r)) * max(1.0, 1.0 / abs(m.dc_gain()))
    # As above: rounding of FFTs and short recursions (measured ~1e-13 of the peak).
    assert_allclose(_loop(m, drive), r, rtol=0, atol=1e-9 * np.max(np.abs(r)))


def test_zero_on_the_circle_inside_the_band_is_refused():
    z = np.exp(1j * 2 * np.pi * 20 * DT)  # |z| = 1 at 20 Hz
    m = _model([z, np.conj(z)], [0.9], 0.1, 1, band=(0.0, 50.0))
    with pytest.raises(ParameterError, match=r"unit circle .* 20 Hz\) inside the band"):
        design_inverse(m)
    # Outside the band limit's support (cutoff 75 Hz) the same zero is no obstacle.
    z = np.exp(1j * 2 * np.pi * 300 * DT)
    m = _model([z, np.conj(z)], [0.9], 0.1, 1, band=(0.0, 50.0))
    r = _in_band_reference()
    assert_allclose(_loop(m, design_inverse(m).apply(r)), r, rtol=0,
                    atol=1e-9 * np.max(np.abs(r)))


# --------------------------------------------------------------------------- checks
def test_compensate_needs_a_band():
    m = _model([0.5], [0.9], 0.1, 1)
    r = _in_band_reference()
    with pytest.raises(ParameterError, match="no validated band"):
        compensate(m, r, fs=FS)
    assert compensate(m, r, fs=FS, band_hz=(0.0, 50.0)).shape == r.shape


def test_compensate_refuses_a_drive_far_beyond_the_reference():
    # A loop whose gain is 0.2 in the band: the exact drive is 5× the reference.
    m = _model([0.5], [0.9], 0.2 * 0.1 / 0.5, 1, band=(0.0, 50.0))
    assert m.dc_gain() == pytest.approx(0.2)
    r = np.sin(np.pi * np.arange(4000) / 3999) ** 2  # slow, at rest at both ends
    with pytest.raises(ParameterError, match=r"RMS is 5× the reference's \(bound 3×\)"):
        compensate(m, r, fs=FS)
    drive = compensate(m, r, fs=FS, max_gain=6.0)
    assert_allclose(np.std(drive) / np.std(r), 5.0, rtol=1e-3)


def test_compensate_refuses_a_reference_not_at_rest():
    m = _model([0.5], [0.9], 0.2, 1, band=(0.0, 50.0))  # G(1) = 1
    r = 0.46 + _in_band_reference()
    with pytest.raises(ParameterError, match="starts at 0.46.*fade it in and out"):
        compensate(m, r, fs=FS)
    faded = fade_to_rest(r, FS, 0.5)
    check_at_rest(faded)
    assert faded[0] == 0.0 and abs(faded[-1]) < 1e-3 * np.max(np.abs(faded))
    compensate(m, faded, fs=FS)


def test_drive_limits_explicit_and_from_the_rig():
    t = np.arange(2000) * DT
    u = 0.05 * np.sin(2 * np.pi * 2.0 * t)  # peak 0.05 m, 0.63 m/s, 7.9 m/s²
    check = check_drive(u, u, FS)
    assert check.rms_gain == pytest.approx(1.0) and check.peak_gain == pytest.approx(1.0)
    # finite differences of a 2 Hz sine at 1 kHz: within 1e-4 of the analytic peaks
    assert check.peak_rate == pytest.approx(0.05 * 2 * np.pi * 2.0, rel=1e-4)
    assert check.peak_rate2 == pytest.approx(0.05 * (2 * np.pi * 2.0) ** 2, rel=1e-4)
    with pytest.raises(ParameterError, match=r"peak rate 0.628\d* exceeds the limit 0.2"):
        check_drive(u, u, FS, limits=DriveLimits(max_rate=0.2))
    with pytest.raises(ParameterError, match=r"second derivative 7.89\d* exceeds"):
        check_drive(u, u, FS, limits=DriveLimits(max_rate2=5.0))
    with pytest.raises(ParameterError, match=r"drive: position reference peak velocity"):
        check_drive(u, u, FS, loop="position", params=preset("default"))
    with pytest.raises(ParameterError, match=r"valve command 12 V exceeds"):
        check_drive(12.0 * np.sin(2 * np.pi * t), np.sin(2 * np.pi * t), FS, max_gain=None,
                    loop="valve", params=preset("default"))
    slow = 0.01 * np.sin(2 * np.pi * 0.5 * t)
    assert check_drive(slow, slow, FS, loop="position",
                       params=preset("default")).rig["peak_velocity_m_s"] > 0
    # value limits apply to the operating point plus the deviation
    check_drive(u, u, FS, limits=DriveLimits(max_abs=0.06))
    with pytest.raises(ParameterError, match=r"drive peak 0.07 exceeds the limit 0.06"):
        check_drive(u, u, FS, limits=DriveLimits(max_abs=0.06), drive_offset=0.02)
    with pytest.raises(TypeError):
        check_drive(u, u, FS, limits={"max_rate": 1.0})
    with pytest.raises(ParameterError, match="max_abs"):
        DriveLimits(max_abs=-1.0)


_radius = st.one_of(st.floats(0.05, 0.9), st.floats(1.1, 5.0))


@settings(max_examples=40, deadline=None)
@given(zeros=st.lists(st.tuples(_radius, st.floats(0.0, np.pi)), min_size=1, max_size=3),
       poles=st.lists(st.tuples(st.floats(0.0, 0.9), st.floats(0.0, np.pi)), min_size=1,
                      max_size=3),
       delay=st.integers(0, 3))
def test_stable_inverse_times_model_is_one_in_the_band(zeros, poles, delay):
    # Any stable model whose zeros keep 0.1 from the unit circle: F·G = 1 wherever the
    # band limit is 1. Complex roots come in conjugate pairs so that B and A are real.
    def roots(pairs):
        out = []
        for r, ang in pairs:
            z = r * np.exp(1j * ang)
            out += [z, np.conj(z)] if 1e-6 < ang < np.pi - 1e-6 else [z.real]
        return out

    m = _model(roots(zeros), roots(poles), 0.1, delay, band=(0.0, 200.0))
    inv = design_inverse(m)
    f = np.linspace(0.0, 200.0, 101)
    overall = inv.frequency_response(f) * _response(m, f)
    # Degree <= 6 polynomials with roots up to radius 5 (coefficients up to ~5^6) evaluated
    # on the unit circle, divided by each other: relative rounding ~1e-12 at worst.
    assert_allclose(overall, 1.0, rtol=0, atol=1e-9)
