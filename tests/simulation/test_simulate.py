"""Closed-loop simulation: step responses, determinism, validation, kernel vs reference."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from ehss.errors import DataError, ParameterError
from ehss.params import preset
from ehss.simulation import SimulationResult, simulate
from ehss.simulation import _kernels as SK

G = 9.80665


def _step(amplitude, n, start=100):
    r = np.zeros(n)
    r[start:] = amplitude
    return r


def _assert_no_limits(r: SimulationResult):
    assert r.limits_hit == {}, r.limits_hit


# ----------------------------------------------------------------------------- steps
def test_position_step_settles_without_error():
    p = preset("default")
    r = simulate("position", _step(0.005, 1500), params=p, seed=1)
    _assert_no_limits(r)
    # the valve-controlled actuator integrates: no steady-state error with any PID.
    # Tolerance 1 % of the step: LVDT noise (2 µm) and LSB (3 µm) averaged over 300 samples
    assert abs(r.output[-300:].mean() - 0.005) < 0.01 * 0.005
    assert abs(r.signals["displacement_m"][-300:].mean() - 0.005) < 0.01 * 0.005


def test_force_step_settles():
    p = preset("default")
    r = simulate("force", _step(1000.0, 1500), params=p, seed=2)
    _assert_no_limits(r)
    final = r.output[-300:].mean()
    if p.force.ki_v_per_n_per_s > 0:
        # integrator: only noise (0.5 N) and quantisation (0.45 N) remain
        assert abs(final - 1000.0) < 2.0
    else:
        # P only: F = r L0/(1 + L0) with the DC loop gain of eqs (8) and (1); 5 % for the
        # orifice's extra Kc at the loaded operating point
        l0 = (p.force.kp_v_per_n * p.valve.gain_per_v * p.flow_gain_m3_s
              * p.actuator.piston_area_m2 / p.kce_m3_s_pa)
        assert final == pytest.approx(1000.0 * l0 / (1 + l0), rel=0.05)


def test_acceleration_step_settles_on_generator_displacement():
    """A 0.02 g step: the generator (eq (10)) turns it into a displacement step of
    Kg a/ωn² (2 cm here; 0.1 g would need 10 cm, the whole stroke), which the TVC holds."""
    p = preset("default")
    a = 0.02 * G
    r = simulate("acceleration", _step(a, 5000), params=p, seed=3)
    _assert_no_limits(r)
    tvc = p.acceleration
    expected = tvc.kdr * tvc.kg * a / tvc.generator_omega_rad_s**2
    # LVDT-type accuracy after 4.9 s (generator settles in ~4/(ζn ωn) = 1.8 s)
    assert r.signals["displacement_m"][-300:].mean() == pytest.approx(expected, rel=0.01)
    # back at rest on average (the loop jitters on the sensor noise)
    assert abs(r.signals["acceleration_m_s2"][-300:].mean()) < 0.05 * a


def test_acceleration_loop_tracks_in_band_sine():
    """In the working band (Table 2: 1–50 Hz) the acceleration follows a 10 Hz sine."""
    p = preset("default")
    fs, f = 1000.0, 10.0
    t = np.arange(3000) / fs
    ref = 0.1 * G * np.sin(2 * np.pi * f * t)
    r = simulate("acceleration", ref, params=p, seed=4)
    _assert_no_limits(r)
    keep = t >= 2.0
    w = 2 * np.pi * f
    basis = np.column_stack([np.sin(w * t[keep]), np.cos(w * t[keep])])
    amp = np.hypot(*np.linalg.lstsq(basis, r.output[keep], rcond=None)[0])
    # ±3 dB: the loop's in-band flatness, whatever the tuning
    assert 10 ** (-3 / 20) < amp / (0.1 * G) < 10 ** (3 / 20)


def test_force_loop_starts_in_equilibrium_on_an_offset():
    """The paper's force sweep runs about 25 kgf: the record starts holding it."""
    f0 = 25 * G
    p = preset("default")
    ideal = dataclasses.replace(p, sensors=dataclasses.replace(
        p.sensors, force_noise_n=0.0, quantize=False))
    r = simulate("force", np.full(300, f0), params=ideal, seed=5)
    # steady state solved to |Ṗ| < 1 kPa/s: the force stays put to a µN-level
    assert abs(r.signals["force_n"] - f0).max() < 1e-6 * f0
    assert abs(r.signals["velocity_m_s"]).max() < 1e-9


def test_limits_are_reported():
    # a 9 cm step in 0.3 s is beyond the valve: the drive saturates
    r = simulate("position", _step(0.09, 300, start=10), seed=6)
    assert r.limit_fractions["drive_saturated"] > 0.05
    assert "drive_saturated" in r.limits_hit


# ----------------------------------------------------------------------------- result
def test_result_columns_and_units():
    r = simulate("position", np.zeros(50), seed=0)
    cols = r.to_columns()
    assert list(cols)[:3] == ["t", "reference", "output"]
    for name in ("drive_v", "spool", "p1_pa", "p2_pa", "load_pressure_pa", "displacement_m",
                 "velocity_m_s", "acceleration_m_s2", "force_n", "lvdt_m", "accel_m_s2",
                 "force_cell_n"):
        assert name in r.signals and r.signals[name].shape == (50,)
    assert set(r.units) == set(cols)
    assert r.units["output"] == "m" and r.units["p1_pa"] == "Pa"
    assert_allclose(np.diff(r.t), 1e-3, rtol=1e-12)
    assert r.loop == "position" and r.fs == 1000.0 and r.seed == 0
    with pytest.raises(ValueError):
        r.output[0] = 1.0  # results are read-only


def test_fs_replaces_the_control_rate():
    r = simulate("position", np.zeros(20), fs=2000.0, seed=0)
    assert r.fs == 2000.0 and r.params.timing.control_rate_hz == 2000.0
    assert r.t[1] == pytest.approx(5e-4)


def test_signal_like_reference():
    class Sig:
        values = np.zeros(10)
        fs = 500.0

    r = simulate("position", Sig(), seed=0)
    assert r.fs == 500.0


# ----------------------------------------------------------------------------- determinism
def test_same_seed_same_record_other_seed_other_noise():
    ref = _step(0.002, 300)
    a = simulate("position", ref, seed=11)
    b = simulate("position", ref, seed=11)
    c = simulate("position", ref, seed=12)
    for name in a.signals:
        assert_array_equal(a.signals[name], b.signals[name])
    assert not np.array_equal(a.signals["lvdt_m"], c.signals["lvdt_m"])


def test_seed_is_recorded_when_drawn():
    r = simulate("position", np.zeros(100))
    again = simulate("position", np.zeros(100), seed=r.seed)
    assert_array_equal(r.output, again.output)


# ----------------------------------------------------------------------------- bad input
@pytest.mark.parametrize(
    ("loop", "ref", "kwargs", "error", "text"),
    [
        ("position", np.array([0.0, np.nan, 1.0]), {}, DataError, "reference[1]"),
        ("position", np.array([]), {}, DataError, "empty"),
        ("position", np.zeros((3, 2)), {}, DataError, "1-D"),
        ("speed", np.zeros(3), {}, ParameterError, "position"),
        ("position", np.zeros(3), {"fs": 3000.0}, ParameterError, "10000"),
        ("position", np.zeros(3), {"seed": -1}, ParameterError, "seed"),
        ("position", np.zeros(3), {"initial_state": {"nope": 1.0}}, ParameterError, "nope"),
        # a wrong initial state: wrong container, wrong value types, non-finite values
        ("position", np.zeros(3), {"initial_state": np.zeros(12)}, TypeError,
         "initial_state must be a mapping of state names to values"),
        ("position", np.zeros(3), {"initial_state": [("displacement_m", 0.01)]}, TypeError,
         "got list"),
        ("position", np.zeros(3), {"initial_state": {"displacement_m": "0.01"}}, TypeError,
         "initial_state['displacement_m']='0.01' must be a real number, not str"),
        ("position", np.zeros(3), {"initial_state": {"displacement_m": None}}, TypeError,
         "must be a real number, not NoneType"),
        ("position", np.zeros(3), {"initial_state": {"displacement_m": np.zeros(2)}},
         TypeError, "not ndarray"),
        ("position", np.zeros(3), {"initial_state": {"displacement_m": 1j}}, TypeError,
         "not complex"),
        ("position", np.zeros(3), {"initial_state": {3: 0.01}}, TypeError,
         "key 3 must be a state name"),
        ("position", np.zeros(3), {"initial_state": {"displacement_m": math.inf}},
         ParameterError, "must be finite"),
    ],
)
def test_bad_input(loop, ref, kwargs, error, text):
    with pytest.raises(error, match=None) as info:
        simulate(loop, ref, **kwargs)
    assert text in str(info.value)
    if "fs" in kwargs:
        assert "3000" in str(info.value)


def test_initial_state():
    p = preset("default")
    quiet = dataclasses.replace(p, sensors=dataclasses.replace(
        p.sensors, lvdt_noise_m=0.0, quantize=False))
    r = simulate("position", np.full(5, 0.01), params=quiet,
                 initial_state={"displacement_m": 0.01}, seed=0)
    assert r.signals["piston_displacement_m"][0] == 0.01
    assert r.output[0] == 0.01


def test_acceleration_loop_starts_with_the_velocity_estimate_at_rest():
    """Table at rest 1 mm off centre, zero reference, no noise: the first drive of the
    TVC (eq (12)) is Kdf (0 − y) − Kvf v̂ − Kaf a with a = 0 and the velocity estimate
    v̂[0] = p v̂[−1] + b_y (y − y) + b_a (a + a) = 0 (the estimate starts from rest)."""
    p = preset("default")
    quiet = dataclasses.replace(p, sensors=dataclasses.replace(
        p.sensors, lvdt_noise_m=0.0, accel_noise_m_s2=0.0, quantize=False))
    r = simulate("acceleration", np.zeros(3), params=quiet,
                 initial_state={"displacement_m": 0.001}, seed=0)
    assert r.signals["accel_m_s2"][0] == 0.0
    # one product: exact; a velocity estimate started at v̂[−1] = y (a length read as a
    # speed) would add −Kvf p y ≈ −8.6 mV
    assert r.signals["drive_v"][0] == -p.acceleration.kdf_v_per_m * 0.001


# ----------------------------------------------------------------------------- kernel
def test_kernel_matches_its_python_source():
    """The compiled loop against its own source run by the interpreter (``py_func``)."""
    from ehss.simulation.core import _kernel_inputs

    p = preset("default")
    ref = np.ascontiguousarray(0.5 * np.sin(np.arange(60) / 5.0))
    x0, noise, settings, mem, _ = _kernel_inputs(
        "acceleration", ref, p, seed=9, initial_state=None, spool_direct=False,
        stiffness_n_m=0.0)
    n_rows = len(SK.LoopRecord._fields)
    fast = SK.LoopRecord._make(np.empty((n_rows, 60)))
    slow = SK.LoopRecord._make(np.empty((n_rows, 60)))
    mem_slow = mem.copy()
    x_fast = SK.closed_loop(ref, noise, x0, settings, fast, mem)
    x_slow = SK.closed_loop.py_func(ref, noise, x0, settings, slow, mem_slow)
    assert_allclose(np.array(fast), np.array(slow), rtol=1e-12, atol=0)
    assert_allclose(np.array(x_fast), np.array(x_slow), rtol=1e-12, atol=0)
    assert_allclose(mem, mem_slow, rtol=1e-12, atol=0)


def test_one_position_loop_against_slow_reference():
    """Sensor → PID → clip → delay → ZOH → RK4 written out in plain Python."""
    from plant import naive  # tests/plant/naive.py (tests/ is on sys.path)

    p = preset("default")
    p = dataclasses.replace(p, sensors=dataclasses.replace(p.sensors, quantize=False))
    n, n_sub, h, dt = 40, 10, 1e-4, 1e-3
    ref = _step(0.004, n, start=2)
    r = simulate("position", ref, params=p, seed=21)
    # the LVDT's noise: the first of the three sensors' draws of each period
    noise = np.random.default_rng(21).standard_normal((n, 3))[:, 0] * p.sensors.lvdt_noise_m
    pid = p.position
    tau = 1 / (2 * math.pi * pid.derivative_filter_hz)
    x = np.zeros(9)
    x[4] = x[5] = p.actuator.supply_pressure_pa / 2
    integ, deriv, y_prev = 0.0, 0.0, None
    line = [0.0] * p.timing.delay_samples
    drives = []
    for k in range(n):
        ym = x[2] + noise[k]
        y_prev = ym if y_prev is None else y_prev
        e = ref[k] - ym
        deriv = tau / (tau + dt) * deriv - pid.kd_v_s_per_m / (tau + dt) * (ym - y_prev)
        u = pid.kp_v_per_m * e + integ + deriv
        lim = pid.output_limit_v
        if not ((u > lim and e > 0) or (u < -lim and e < 0)):
            integ += pid.ki_v_per_m_per_s * e * dt
        y_prev = ym
        u = min(lim, max(-lim, u))
        drives.append(u)
        line.append(u)
        applied = line.pop(0)
        for _ in range(n_sub):
            x = naive.rk4(x, applied / p.valve.command_full_scale_v + p.valve.null_bias, p,
                          k_n_m=0.0, h=h)
        if k + 1 < n:
            assert_allclose(r.signals["p1_pa"][k + 1], x[4], rtol=1e-12)
            assert_allclose(r.signals["displacement_m"][k + 1], x[6], rtol=1e-12, atol=1e-18)
    assert_allclose(r.signals["drive_v"], drives, rtol=1e-12, atol=1e-15)


def test_force_reference_starting_near_zero_starts_at_rest():
    # A reference whose first value is rounding noise (a band-limited random signal starts
    # at ~1e-13 N) must not ask the plant for a steady state it cannot resolve.
    ref = np.full(200, 2.4e-13)
    run = simulate("force", ref, seed=1)
    assert run.signals["spool"][0] == 0.0
    assert np.all(np.isfinite(run.output))
