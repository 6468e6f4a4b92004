"""Tests of ehss.linear against hand-computed values of the paper's equations."""

from __future__ import annotations

import dataclasses
import math

import control as ct
import numpy as np
import pytest
from numpy.testing import assert_allclose

from ehss import linear as lin
from ehss.errors import ParameterError
from ehss.params import preset


@pytest.fixture
def params():
    return preset("default")


def test_valve_eq1_magnitude_at_natural_frequency(params):
    # At ω = ωv eq (1) is Kv / (2jζv): |G| = Kv/(2ζv), phase −90°
    g = lin.response_at(lin.valve(params), params.valve.natural_freq_hz)
    assert_allclose(abs(g), 0.1 / (2 * 0.7), rtol=1e-12)  # exact rational evaluation
    assert_allclose(np.angle(g, deg=True), -90.0, atol=1e-9)


def test_position_open_loop_eq7_by_hand(params):
    f = 10.0
    w = 2 * math.pi * f
    wh, zh, k0 = params.hydraulic_omega_rad_s, params.hydraulic_damping, params.velocity_gain_m_s
    # |G| = K0 / (ω |1 − ω²/ωh² + 2jζh ω/ωh|)
    expected = k0 / (w * math.hypot(1 - (w / wh) ** 2, 2 * zh * w / wh))
    assert_allclose(abs(lin.response_at(lin.position_open_loop(params), f)), expected, rtol=1e-12)


def test_position_open_loop_poles_are_omega_h(params):
    poles = lin.position_open_loop(params).poles()
    osc = poles[np.abs(poles) > 1.0]
    # the oscillatory pair has |p| = ωh and damping −Re(p)/|p| = ζh (root finding: 1e-9)
    assert_allclose(np.abs(osc), params.hydraulic_omega_rad_s, rtol=1e-9)
    assert_allclose(-osc.real / np.abs(osc), params.hydraulic_damping, rtol=1e-9)
    assert np.min(np.abs(poles)) < 1e-9  # the integrator


def test_exact_plant_differs_from_eq7_by_kce_bp_term(params):
    # eq (5)–(6) at low frequency: velocity gain K0/(1 + Kce Bp/Ap²)
    eps = params.kce_m3_s_pa * params.load.damping_n_s_m / params.actuator.piston_area_m2**2
    f = 1e-3
    ratio = lin.response_at(lin.position_open_loop(params, exact=True), f) / lin.response_at(
        lin.position_open_loop(params), f
    )
    assert_allclose(abs(ratio), 1 / (1 + eps), rtol=1e-5)  # residual O((ω/ωh)²) ~ 1e-9


def test_force_open_loop_dc_gain_eq8(params):
    expected = params.flow_gain_m3_s * params.actuator.piston_area_m2 / params.kce_m3_s_pa
    assert_allclose(float(lin.force_open_loop(params).dcgain()), expected, rtol=1e-12)


def test_force_open_loop_close_to_exact_cubic(params):
    # exact: Kq Ap (mt s² + Bp s + K) / [Ap² s + (Kce + Vt s/4βe)(mt s² + Bp s + K)]
    a, ld = params.actuator, params.load
    comp = a.total_volume_m3 / (4 * a.bulk_modulus_pa)
    load = [ld.mass_kg, ld.damping_n_s_m, ld.specimen_stiffness_n_m]
    den = np.polyadd(np.polymul([comp, params.kce_m3_s_pa], load), [a.piston_area_m2**2, 0])
    exact = ct.tf(np.polymul(load, [params.flow_gain_m3_s * a.piston_area_m2]), den)
    f = np.geomspace(0.1, 300, 50)
    ratio = lin.response_at(lin.force_open_loop(params), f) / lin.response_at(exact, f)
    # eq (8) is a factorisation that neglects small cross terms: within 2 % here
    assert np.all(np.abs(np.abs(ratio) - 1) < 0.02)


def test_position_closed_loop_p_only_is_eq9(params):
    p = dataclasses.replace(params, position=dataclasses.replace(
        params.position, kp_v_per_m=500.0, ki_v_per_m_per_s=0.0))
    t = lin.position_closed_loop(p)
    s = 2j * math.pi * 15.0
    wv, zv = params.valve.omega_rad_s, params.valve.damping
    wh, zh = params.hydraulic_omega_rad_s, params.hydraulic_damping
    k = 0.1 * 500.0 * params.velocity_gain_m_s
    d = s * (s**2 / wv**2 + 2 * zv * s / wv + 1) * (s**2 / wh**2 + 2 * zh * s / wh + 1)
    assert_allclose(lin.response_at(t, 15.0), k / (d + k), rtol=1e-10)
    assert_allclose(float(t.dcgain()), 1.0, rtol=1e-12)


def test_discrete_position_loop_matches_continuous_at_low_frequency(params):
    # at 0.5 Hz ZOH + delay add ~0.5° of lag and the exact plant differs from eq (7) only
    # in the oil-column terms: closed loops agree within 0.5 %
    td = lin.position_closed_loop(params, discrete=True)
    tc = lin.position_closed_loop(params, exact=True)
    assert td.dt == params.timing.dt_s
    assert_allclose(lin.response_at(td, 0.5), lin.response_at(tc, 0.5), rtol=5e-3)


def test_discrete_delay_adds_linear_phase(params):
    # one extra sample of delay in the loop → open-loop phase lag of 360° f dt more
    p2 = dataclasses.replace(params, timing=dataclasses.replace(params.timing, delay_samples=2))
    f = 20.0
    l1 = lin.response_at(lin.loop_gain(params, "force"), f)
    l2 = lin.response_at(lin.loop_gain(p2, "force"), f)
    assert_allclose(l2 / l1, np.exp(-2j * math.pi * f * params.timing.dt_s), rtol=1e-9)


def test_acceleration_continuous_pole_placement_gives_eq13():
    # fast valve: the TVC closed loop approaches Kg s²/[(s² + ωg s + δg)(s/ωd + 1)]
    from ehss.control.tuning import tvc_pole_placement

    p = preset("default")
    p = dataclasses.replace(p, valve=dataclasses.replace(p.valve, natural_freq_hz=1e5))
    wd = 2 * math.pi * 10.0
    acc = dataclasses.replace(p.acceleration, **tvc_pole_placement(p, wd))
    p = dataclasses.replace(p, acceleration=acc)
    t = lin.acceleration_closed_loop(p, exact=True)
    f = np.array([1.0, 10.0, 50.0])
    s = 2j * np.pi * f
    wg = 2 * acc.generator_damping * acc.generator_omega_rad_s
    eq13 = acc.kg * s**2 / ((s**2 + wg * s + acc.generator_omega_rad_s**2) * (s / wd + 1))
    # the valve at 100 kHz leaves ~1e-3 of phase error at 50 Hz
    assert_allclose(lin.response_at(t, f), eq13, rtol=2e-3)


def test_margins_analytic():
    # L = 2/(s+1)³: phase −180° at ω = √3, |L| = 2/8 → GM = 20 log10 4
    m = lin.margins(ct.tf([2.0], [1.0, 3.0, 3.0, 1.0]))
    assert_allclose(m.gain_margin_db, 20 * math.log10(4), rtol=1e-6)  # grid interpolation
    assert_allclose(m.phase_crossover_hz, math.sqrt(3) / (2 * math.pi), rtol=1e-4)
    gm, pm, _, _ = ct.margin(ct.tf([2.0], [1.0, 3.0, 3.0, 1.0]))
    assert_allclose(m.phase_margin_deg, pm, rtol=1e-4)


def test_margins_agree_with_python_control_on_discrete_p_loop(params):
    p = dataclasses.replace(params, position=dataclasses.replace(
        params.position, ki_v_per_m_per_s=0.0))
    loop = lin.loop_gain(p, "position")
    gm = ct.stability_margins(ct.tf(loop), method="poly")[0]
    assert_allclose(lin.margins(loop).gain_margin_db, 20 * math.log10(gm), atol=1e-3)


def test_bandwidth_first_order():
    # 1/(s/ω + 1) is 3.0103 dB down at ω; with drop_db = 20 log10 √2 exactly at ω
    bw = lin.bandwidth_hz(ct.tf([1.0], [1 / (2 * math.pi * 7.0), 1.0]),
                          drop_db=10 * math.log10(2))
    assert_allclose(bw, 7.0, rtol=1e-5)


def test_bad_loop_name(params):
    with pytest.raises(ParameterError, match="loop='speed'"):
        lin.loop_gain(params, "speed")


def test_force_model_needs_stiffness(params):
    p = dataclasses.replace(params, load=dataclasses.replace(
        params.load, specimen_stiffness_n_m=0.0))
    with pytest.raises(ParameterError, match="specimen_stiffness_n_m"):
        lin.force_open_loop(p)
