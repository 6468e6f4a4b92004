"""The simulator's RK4 plant against scipy's ODE solution of the same equations.

Open loop with the spool prescribed (held over each control period), the default rig:
the plant's ODE (eqs (2)–(6) with the orifice flows, ``naive.derivative``) does not depend
on the integration step there (no friction, clearance or end stop is reached), so
scipy's ``solve_ivp`` (DOP853, tolerances far below RK4's error) gives the exact
trajectory, and the simulator's error must be the classical RK4 truncation error: of
order h⁴, estimated from a second run at h/2 by Richardson's rule
x_h − x ≈ 16/15 (x_h − x_{h/2}).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.testing import assert_allclose
from scipy.integrate import solve_ivp

from ehss.params import preset
from ehss.simulation import simulate_open_loop

from . import naive

N = 120
FS = 1000.0


def _spool():
    t = np.arange(N) / FS
    return 0.05 * np.sin(2 * np.pi * 40 * t) + 0.03 * np.sin(2 * np.pi * 97 * t + 0.4)


def _run(p, internal_rate_hz):
    p = dataclasses.replace(p, timing=dataclasses.replace(
        p.timing, control_rate_hz=FS, internal_rate_hz=internal_rate_hz, delay_samples=0))
    r = simulate_open_loop(_spool(), params=p, seed=0)
    return np.array([r.signals[k] for k in ("displacement_m", "velocity_m_s", "p1_pa",
                                             "p2_pa")])


def _ode(p):
    a = p.actuator
    pc = (a.supply_pressure_pa + a.return_pressure_pa) / 2
    x = np.array([0, 0, 0, 0, pc, pc, 0, 0, 0], float)
    spool = _spool()
    out = np.empty((4, N))
    # absolute tolerance per state: far below RK4's error in each unit
    atol = np.array([1e-12, 1e-12, 1e-14, 1e-12, 1e-6, 1e-6, 1e-14, 1e-12, 1e-12])
    for k in range(N):
        x[0] = spool[k]
        out[:, k] = x[6], x[7], x[4], x[5]

        def f(_t, z):
            return naive.derivative(z, 0.0, p, k_n_m=0.0, h=1e-4, spool_direct=True)

        sol = solve_ivp(f, (0.0, 1 / FS), x, method="DOP853", rtol=1e-13, atol=atol)
        x = sol.y[:, -1].copy()
    return out


def test_rk4_plant_follows_the_ode_to_its_truncation_error():
    p = preset("default")
    x_h = _run(p, 10_000.0)
    x_h2 = _run(p, 20_000.0)
    exact = _ode(p)
    err = x_h - exact
    predicted = 16 / 15 * (x_h - x_h2)
    for row, name in enumerate(("displacement", "velocity", "p1", "p2")):
        scale = np.abs(exact[row]).max()
        # the error is small: RK4 at ωh h ≈ 0.02 leaves ~(ωh h)⁴/100 ≈ 1e-9 of the scale
        assert np.abs(err[row]).max() < 1e-7 * scale, name
        # ... and is RK4's own h⁴ error: Richardson's estimate predicts it to within its
        # O(h⁵) remainder, taken as 10 % of the error's size (plus the ODE solver's rtol)
        assert_allclose(err[row], predicted[row], rtol=0,
                        atol=0.1 * np.abs(err[row]).max() + 1e-12 * scale, err_msg=name)
