"""Every closed loop against a slow reference written from the equations.

The reference is plain Python: the plant of ``tests/plant/naive.py`` (eqs (1)–(6) from
the RigParams fields), the sensors with noise and ADC quantisation, the controllers from
their laws (PID of eqs (9) and (15); TVC of eqs (10)–(12) and Fig. 6 with the generator
discretised by scipy's ``cont2discrete`` and the velocity filter by scipy's
``bilinear``), the output limit, the DAC, the delay line and the ZOH. It shares no code
with the kernels, so a packing or layout mistake in the typed settings shows up here.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import scipy.signal
from numpy.testing import assert_allclose

from ehss.params import RigParams, preset
from ehss.simulation import simulate
from plant import naive  # tests/plant/naive.py (tests/ is on sys.path)

N = 60


def _quantise(value: float, full_scale: float, lsb: float) -> float:
    if lsb <= 0.0:
        return value
    return min(full_scale, max(-full_scale, round(value / lsb) * lsb))


def _friction(v: float, p: RigParams, h: float) -> float:
    ld = p.load
    fsum = ld.coulomb_friction_n + ld.stribeck_friction_n
    if fsum == 0:
        return 0.0
    v_eps = max(1e-5, 2 * fsum * h / ld.mass_kg)  # rigid joint: friction acts on mt
    stribeck = math.exp(-((v / ld.stribeck_velocity_m_s) ** 2))
    return math.tanh(v / v_eps) * (ld.coulomb_friction_n + ld.stribeck_friction_n * stribeck)


class _Pid:
    """u = kp e + I + D; D filtered (backward Euler), derivative on measurement."""

    def __init__(self, kp, ki, kd, *, filter_hz, limit, dt):
        self.kp, self.ki, self.kd, self.limit, self.dt = kp, ki, kd, limit, dt
        self.tau = 1 / (2 * math.pi * filter_hz)
        self.integ = self.deriv = 0.0
        self.y_prev = None

    def __call__(self, r, y):
        if self.y_prev is None:
            self.y_prev = y  # no derivative kick
        e = r - y
        self.deriv = (self.tau / (self.tau + self.dt) * self.deriv
                      - self.kd / (self.tau + self.dt) * (y - self.y_prev))
        u = self.kp * e + self.integ + self.deriv
        if not ((u > self.limit and e > 0) or (u < -self.limit and e < 0)):
            self.integ += self.ki * e * self.dt
        self.y_prev = y
        return u, r


class _Tvc:
    """Generator (eq (10), ZOH), velocity synthesis (Fig. 6, Tustin) and eq (12)."""

    def __init__(self, tvc, dt):
        wn = tvc.generator_omega_rad_s
        wg, dg = 2 * tvc.generator_damping * wn, wn * wn
        self.gen = (tvc.kg, wg, dg)
        a = np.array([[0.0, 1.0], [-dg, -wg]])
        b = np.array([[0.0], [tvc.kg]])
        self.phi, gam, *_ = scipy.signal.cont2discrete(
            (a, b, np.eye(2), np.zeros((2, 1))), dt, "zoh")
        self.gam = gam[:, 0]
        wc = 2 * math.pi * tvc.velocity_crossover_hz
        # v̂ = [ωc s/(s+ωc)] y + [1/(s+ωc)] a, each by the bilinear transform
        self.by, self.ay = scipy.signal.bilinear([wc, 0.0], [1.0, wc], fs=1 / dt)
        self.ba, _ = scipy.signal.bilinear([1.0], [1.0, wc], fs=1 / dt)
        self.t = tvc
        self.gen_state = np.zeros(2)  # r_d, v_d
        self.v_hat = 0.0  # starts from rest
        self.prev = None

    def __call__(self, ar, y, a):
        if self.prev is None:
            self.prev = (y, a)
        kg, wg, dg = self.gen
        rd, vd = self.gen_state
        ad = kg * ar - wg * vd - dg * rd
        y_prev, a_prev = self.prev
        self.v_hat = (-self.ay[1] * self.v_hat + self.by[0] * y + self.by[1] * y_prev
                      + self.ba[0] * a + self.ba[1] * a_prev)
        t = self.t
        u = (t.kdf_v_per_m * (t.kdr * rd + t.kvr_s * vd + t.kar_s2 * ad - y)
             - t.kvf_v_per_m_s * self.v_hat - t.kaf_v_per_m_s2 * a)
        self.gen_state = self.phi @ self.gen_state + self.gam * ar
        self.prev = (y, a)
        return u, ad


def _controller(loop, p, dt):
    if loop == "acceleration":
        c = _Tvc(p.acceleration, dt)
        return c, p.acceleration.output_limit_v
    if loop == "position":
        g = p.position
        gains = (g.kp_v_per_m, g.ki_v_per_m_per_s, g.kd_v_s_per_m)
    else:
        g = p.force
        gains = (g.kp_v_per_n, g.ki_v_per_n_per_s, g.kd_v_s_per_n)
    pid = _Pid(*gains, filter_hz=g.derivative_filter_hz, limit=g.output_limit_v, dt=dt)
    return pid, g.output_limit_v


def slow_loop(loop: str, ref: np.ndarray, p: RigParams, seed: int) -> dict[str, np.ndarray]:
    """The records of ``simulate(loop, ref, params=p, seed=seed)``, computed slowly."""
    tm, s, a_ = p.timing, p.sensors, p.actuator
    dt, h = 1 / tm.control_rate_hz, 1 / tm.internal_rate_hz
    k_n_m = p.load.specimen_stiffness_n_m if loop == "force" else p.load.stiffness_n_m
    n = ref.size
    # the simulator's noise convention: one standard-normal (n, 3) draw, period by period
    # (so that a test continued in blocks draws the same), scaled per sensor
    sigma = np.array([s.lvdt_noise_m, s.accel_noise_m_s2, s.force_noise_n])
    noise = (np.random.default_rng(seed).standard_normal((n, 3)) * sigma).T
    bits = 2.0**s.adc_bits
    lsb = {"lvdt": 2 * s.lvdt_range_m / bits, "accel": 2 * s.accel_range_m_s2 / bits,
           "force": 2 * s.force_range_n / bits, "dac": 20 / 2.0**s.dac_bits}
    if not s.quantize:
        lsb = dict.fromkeys(lsb, 0.0)
    pc = (a_.supply_pressure_pa + a_.return_pressure_pa) / 2
    x = np.array([p.valve.null_bias, 0, 0, 0, pc, pc, 0, 0, 0], float)
    ctl, limit = _controller(loop, p, dt)
    line = [0.0] * tm.delay_samples
    out = {k: np.zeros(n) for k in ("drive_v", "valve_command_v", "p1_pa", "displacement_m",
                                    "acceleration_m_s2", "force_n", "lvdt_m", "accel_m_s2",
                                    "force_cell_n", "aux")}
    for k in range(n):
        a_table = naive.derivative(x, 0.0, p, k_n_m=k_n_m, h=h)[7]
        f_true = a_.piston_area_m2 * (x[4] - x[5]) - _friction(x[3], p, h)
        a_hp = a_table - 2 * math.pi * s.accel_highpass_hz * x[8]
        ym = _quantise(x[2] + noise[0, k], s.lvdt_range_m, lsb["lvdt"])
        am = _quantise(a_hp + noise[1, k], s.accel_range_m_s2, lsb["accel"])
        fm = _quantise(f_true + noise[2, k], s.force_range_n, lsb["force"])
        if loop == "acceleration":
            u, aux = ctl(ref[k], ym, am)
        else:
            u, aux = ctl(ref[k], fm if loop == "force" else ym)
        u = _quantise(min(limit, max(-limit, u)), 10.0, lsb["dac"])
        line.append(u)
        applied = line.pop(0)
        for name, value in (("drive_v", u), ("valve_command_v", applied), ("p1_pa", x[4]),
                            ("displacement_m", x[6]), ("acceleration_m_s2", a_table),
                            ("force_n", f_true), ("lvdt_m", ym), ("accel_m_s2", am),
                            ("force_cell_n", fm), ("aux", aux)):
            out[name][k] = value
        for _ in range(tm.substeps):
            x = naive.rk4(x, applied / p.valve.command_full_scale_v + p.valve.null_bias, p,
                          k_n_m=k_n_m, h=h)
    return out


def _reference(loop):
    t = np.arange(N) * 1e-3
    shape = np.sin(2 * np.pi * 23 * t) + 0.5 * np.sin(2 * np.pi * 61 * t + 1.0)
    shape[:3] = 0.0  # the force loop starts at rest on a zero reference
    return {"position": 1e-3 * shape, "acceleration": 3.0 * shape, "force": 800.0 * shape}[loop]


@pytest.mark.parametrize("loop", ["position", "acceleration", "force"])
@pytest.mark.parametrize("variant", ["default", "friction_no_delay"])
def test_loop_matches_slow_reference(loop, variant):
    p = preset("default")
    if variant == "friction_no_delay":
        p = dataclasses.replace(
            p, load=dataclasses.replace(p.load, coulomb_friction_n=400.0,
                                        stribeck_friction_n=150.0),
            timing=dataclasses.replace(p.timing, delay_samples=0))
    ref = _reference(loop)
    run = simulate(loop, ref, params=p, seed=17)
    slow = slow_loop(loop, ref, p, seed=17)
    assert run.limits_hit == {}  # the reference models no limit beyond the output clip
    got = dict(run.signals)
    got["aux"] = got.get("generated_acceleration_m_s2", run.reference)
    for name, expected in slow.items():
        scale = np.abs(expected).max()
        # Same equations, operations in another order, Φ by another matrix exponential:
        # rounding (1e-16) grown through 60 periods of a stable loop stays far below
        # 1e-10 of each signal's scale; a quantiser flip or a mislabelled coefficient
        # would show as a whole LSB (1e-4 of scale) or more.
        assert_allclose(got[name], expected, rtol=0, atol=1e-10 * scale, err_msg=name)
