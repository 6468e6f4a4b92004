"""The plant kernels against the slow reference in ``naive.py``."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from numpy.testing import assert_allclose

from ehss.params import preset
from ehss.plant import _kernels as K
from ehss.plant.model import plant_parameter_vector, rest_state

from . import naive

H = 1e-4


def _params(**load):
    p = preset("default")
    return dataclasses.replace(p, load=dataclasses.replace(p.load, **load))


def _random_state(rng, p):
    ps = p.actuator.supply_pressure_pa
    x = rest_state(p)
    x[K.X_SPOOL] = rng.uniform(-0.8, 0.8)
    x[K.X_SPOOL_RATE] = rng.uniform(-50, 50)
    x[K.X_POS] = rng.uniform(-0.05, 0.05)
    x[K.X_VEL] = rng.uniform(-0.2, 0.2)
    x[K.X_P1] = rng.uniform(0.1, 0.9) * ps
    x[K.X_P2] = rng.uniform(0.1, 0.9) * ps
    x[K.X_TABLE_POS] = x[K.X_POS] + rng.uniform(-3e-5, 3e-5)
    x[K.X_TABLE_VEL] = x[K.X_VEL] + rng.uniform(-1e-3, 1e-3)
    x[K.X_HP] = rng.uniform(-0.1, 0.1)
    return x


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
    prm = plant_parameter_vector(p, stiffness_n_m=k, internal_dt_s=H)
    work = np.empty((5, K.N_STATE))
    dx = np.empty(K.N_STATE)
    for _ in range(20):
        x = _random_state(rng, p)
        if case in ("linear", "stiff"):
            x[K.X_TABLE_POS], x[K.X_TABLE_VEL] = x[K.X_POS], x[K.X_VEL]
        ucmd = rng.uniform(-1.2, 1.2)
        K.plant_derivative(x, ucmd, prm, dx)
        ref = naive.derivative(x, ucmd, p, k_n_m=k, h=H)
        # same operations in a different order: agreement to a few ulps of the largest term
        assert_allclose(dx, ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max())
        xk = x.copy()
        K.rk4_step(xk, ucmd, prm, H, work)
        K.clamp_state(xk, prm)
        xr = naive.rk4(x, ucmd, p, k_n_m=k, h=H)
        assert_allclose(xk, xr, rtol=1e-12, atol=1e-9)  # atol: pressures ~1e7 Pa × 1e-16


def test_signed_sqrt_is_a_signed_root_with_a_smooth_core():
    lam = 7e3
    dp = np.array([-1e7, -1e5, 0.0, 1e5, 1e7])
    out = np.array([K.signed_sqrt(d, lam) for d in dp])
    assert_allclose(out[[0, 4]], [-np.sqrt(1e7), np.sqrt(1e7)], rtol=lam / 1e7)
    assert out[2] == 0.0 and np.all(np.diff(out) > 0)


def test_clamps():
    p = preset("default")
    prm = plant_parameter_vector(p, stiffness_n_m=0.0, internal_dt_s=H)
    x = rest_state(p)
    x[K.X_P1], x[K.X_P2], x[K.X_SPOOL], x[K.X_SPOOL_RATE] = -5.0, 3e7, 1.2, 4.0
    K.clamp_state(x, prm)
    assert (x[K.X_P1], x[K.X_P2]) == (0.0, p.actuator.supply_pressure_pa)
    assert (x[K.X_SPOOL], x[K.X_SPOOL_RATE]) == (1.0, 0.0)


def test_adc_quantises_and_clips():
    assert K.adc(0.1234, 1.0, 0.01) == pytest.approx(0.12)
    assert K.adc(5.0, 1.0, 0.01) == 1.0
    assert K.adc(0.1234, 1.0, 0.0) == 0.1234
