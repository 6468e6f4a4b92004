"""The plant kernels against the slow reference in ``naive.py``."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from numpy.testing import assert_allclose

from ehss.params import preset
from ehss.plant import kernels as K
from ehss.plant.model import STATE_NAMES, plant_settings, rest_state

from . import naive

H = 1e-4


def _params(**load):
    p = preset("default")
    return dataclasses.replace(p, load=dataclasses.replace(p.load, **load))


def _random_state(rng, p, *, rigid):
    ps = p.actuator.supply_pressure_pa
    y = rng.uniform(-0.05, 0.05)
    v = rng.uniform(-0.2, 0.2)
    return K.PlantState(
        spool=rng.uniform(-0.8, 0.8),
        spool_rate_1_s=rng.uniform(-50, 50),
        piston_displacement_m=y,
        piston_velocity_m_s=v,
        p1_pa=rng.uniform(0.1, 0.9) * ps,
        p2_pa=rng.uniform(0.1, 0.9) * ps,
        displacement_m=y if rigid else y + rng.uniform(-3e-5, 3e-5),
        velocity_m_s=v if rigid else v + rng.uniform(-1e-3, 1e-3),
        accel_highpass_state_m_s=rng.uniform(-0.1, 0.1),
    )


CASES = {
    "linear": {},
    "friction": {"coulomb_friction_n": 800.0, "stribeck_friction_n": 300.0},
    "clearance": {"clearance_m": 4e-5, "coulomb_friction_n": 500.0},
    "stiff": {"stiffness_n_m": 2e7},
}


@pytest.mark.parametrize("case", CASES)
def test_derivative_and_rk4_match_reference(rng, case):
    p = _params(**CASES[case])
    k = p.load.stiffness_n_m
    s = plant_settings(p, stiffness_n_m=k, internal_dt_s=H)
    for _ in range(20):
        x = _random_state(rng, p, rigid=case in ("linear", "stiff"))
        ucmd = rng.uniform(-1.2, 1.2)
        dx = np.array(K.plant_derivative(x, ucmd, s))
        ref = naive.derivative(np.array(x), ucmd, p, k_n_m=k, h=H)
        # same operations in a different order: agreement to a few ulps of the largest term
        assert_allclose(dx, ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max())
        xk = np.array(K.clamp_state(K.rk4_step(x, ucmd, s, H), s))
        xr = naive.rk4(np.array(x), ucmd, p, k_n_m=k, h=H)
        assert_allclose(xk, xr, rtol=1e-12, atol=1e-9)  # atol: pressures ~1e7 Pa × 1e-16


def test_signed_sqrt_is_a_signed_root_with_a_smooth_core():
    lam = 7e3
    dp = np.array([-1e7, -1e5, 0.0, 1e5, 1e7])
    out = np.array([K.signed_sqrt(d, lam) for d in dp])
    assert_allclose(out[[0, 4]], [-np.sqrt(1e7), np.sqrt(1e7)], rtol=lam / 1e7)
    assert out[2] == 0.0 and np.all(np.diff(out) > 0)


def test_clamps():
    p = preset("default")
    s = plant_settings(p, stiffness_n_m=0.0, internal_dt_s=H)
    x = rest_state(p)._replace(p1_pa=-5.0, p2_pa=3e7, spool=1.2, spool_rate_1_s=4.0)
    x = K.clamp_state(x, s)
    assert (x.p1_pa, x.p2_pa) == (0.0, p.actuator.supply_pressure_pa)
    assert (x.spool, x.spool_rate_1_s) == (1.0, 0.0)
    # pushing back inward from the stop keeps its rate
    x = K.clamp_state(x._replace(spool=-1.5, spool_rate_1_s=3.0), s)
    assert (x.spool, x.spool_rate_1_s) == (-1.0, 3.0)


def test_state_names_are_the_kernel_state():
    # the names accepted by simulate(initial_state=...) are the kernel's fields, in order
    assert STATE_NAMES == K.PlantState._fields
    assert rest_state(preset("default"))._fields == STATE_NAMES


def test_settings_are_floats_whatever_the_parameter_types():
    # integer-valued parameters must not give the kernels a second compiled signature
    p = _params(stiffness_n_m=0, clearance_m=0)
    s = plant_settings(p, stiffness_n_m=0, internal_dt_s=H)
    assert all(type(v) is (bool if f in ("spool_saturates", "spool_prescribed") else float)
               for f, v in zip(s._fields, s, strict=True))


def test_adc_quantises_and_clips():
    assert K.adc(0.1234, 1.0, 0.01) == pytest.approx(0.12)
    assert K.adc(5.0, 1.0, 0.01) == 1.0
    assert K.adc(0.1234, 1.0, 0.0) == 0.1234
