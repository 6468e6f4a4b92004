from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal as sps

from ehss import preset, signals, simulate
from ehss.control.known import accelerometer_filter, generator_filter, known_factors
from ehss.errors import ParameterError
from ehss.identification.known import compose
from ehss.identification.model import ArmaxModel


def test_generator_filter_reproduces_the_controller(rng):
    p = preset("default")
    ref = signals.band_limited_random(band_hz=(2, 100), duration_s=2.0, fs=1000.0, seed=5,
                                      peak=2.0)
    run = simulate("acceleration", ref, params=p, seed=5)
    num, den = generator_filter(p)
    a_d = sps.lfilter(num, den, run.reference)
    # Same recursion as the controller's, in another order of operations: rounding only.
    np.testing.assert_allclose(a_d, run.signals["generated_acceleration_m_s2"], rtol=0,
                               atol=1e-12 * np.max(np.abs(a_d)))


def test_generator_filter_matches_eq_10_in_frequency():
    p = preset("default")
    g = p.acceleration
    num, den = generator_filter(p)
    wg, dg = 2 * g.generator_damping * g.generator_omega_rad_s, g.generator_omega_rad_s**2
    # Independent route: scipy's state-space to transfer-function of the same (Φ, Γ, C, D).
    from ehss.control.discrete import generator_zoh

    phi, gam = generator_zoh(g.kg, wg, dg, 1e-3)
    n2, d2 = sps.ss2tf(phi, gam.reshape(2, 1), np.array([[-dg, -wg]]), np.array([[g.kg]]))
    np.testing.assert_allclose(num, n2[0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(den, d2, rtol=0, atol=1e-12)
    # Against the continuous Kg s²/(s² + ωg s + δg): the sampled law differs by
    # O(δg dt) ≈ 1e-2 relative at the lowest frequency and less above; 1.5 % bounds it.
    f = np.array([0.2, 1.0, 5.0, 20.0])
    s_ = 1j * 2 * np.pi * f
    analytic = g.kg * s_**2 / (s_**2 + wg * s_ + dg)
    _, h = sps.freqz(num, den, worN=f, fs=1000.0)
    np.testing.assert_allclose(h, analytic, rtol=1.5e-2)


def test_accelerometer_filter_is_the_first_order_high_pass():
    p = preset("default")
    num, den = accelerometer_filter(p)
    f = np.array([0.1, 0.5, 2.0, 10.0])
    wa = 2 * math.pi * p.sensors.accel_highpass_hz
    analytic = 1j * 2 * np.pi * f / (1j * 2 * np.pi * f + wa)
    _, h = sps.freqz(num, den, worN=f, fs=1000.0)
    # Bilinear frequency warping at f ≤ 10 Hz, fs = 1 kHz: relative error < 1e-3.
    np.testing.assert_allclose(h, analytic, rtol=1e-3)
    assert np.abs(h[1]) == pytest.approx(1 / math.sqrt(2), rel=1e-5)


def test_compose_multiplies_the_responses():
    p = preset("default")
    num, den = known_factors("acceleration", p)
    m = ArmaxModel(a=[1.0, -1.2, 0.5], b=[0.2, 0.1], c=[1.0, 0.3], delay=1, dt=1e-3)
    full = compose(m, num, den)
    f = np.linspace(0.5, 200, 50)
    # Evaluating the product polynomials near their roots at z ≈ 0.997 (0.5 Hz) loses
    # about eight digits against multiplying the factors' responses: rtol 1e-7.
    _, h = sps.freqz(num, den, worN=f, fs=1000.0)
    np.testing.assert_allclose(full.frequency_response(f), h * m.frequency_response(f),
                               rtol=1e-7)
    assert known_factors("position", p)[0].tolist() == [1.0]
    with pytest.raises(ParameterError, match="loop"):
        known_factors("speed", p)
