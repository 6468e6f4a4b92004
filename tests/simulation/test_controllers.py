"""Discrete controller coefficients against scipy's discretisations and a plain PID."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.signal
from numpy.testing import assert_allclose

from ehss.control import kernels as CK
from ehss.control.discrete import (
    complementary_velocity_tustin,
    generator_zoh,
    pid_coefficients,
    tvc_coefficients,
)
from ehss.params import PositionPidParams, TvcParams

DT = 1e-3


@pytest.mark.parametrize(("wn", "dt"), [(3.14, DT), (40.0, 0.2)])  # 2nd: scaling + squaring
def test_generator_zoh_matches_cont2discrete(wn, dt):
    kg, wg, dg = 0.85, 2 * 0.7 * wn, wn**2
    a = np.array([[0.0, 1.0], [-dg, -wg]])
    b = np.array([[0.0], [kg]])
    ad, bd, *_ = scipy.signal.cont2discrete((a, b, np.eye(2), np.zeros((2, 1))), dt, "zoh")
    phi, gam = generator_zoh(kg, wg, dg, dt)
    # two matrix-exponential algorithms: agreement to rounding
    assert_allclose(phi, ad, rtol=1e-12, atol=1e-15)
    assert_allclose(gam, bd[:, 0], rtol=1e-10, atol=1e-16)


def test_complementary_filter_matches_bilinear():
    wc = 2 * math.pi * 5.0
    p, by, ba = complementary_velocity_tustin(wc, DT)
    # v̂ = [ωc s/(s+ωc)] y + [1/(s+ωc)] a
    by_ref, ay_ref = scipy.signal.bilinear([wc, 0.0], [1.0, wc], fs=1 / DT)
    ba_ref, aa_ref = scipy.signal.bilinear([1.0], [1.0, wc], fs=1 / DT)
    assert_allclose([1.0, -p], ay_ref, rtol=1e-12)
    assert_allclose([by, -by], by_ref, rtol=1e-12)
    assert_allclose([ba, ba], ba_ref, rtol=1e-12)
    assert_allclose(aa_ref, ay_ref, rtol=1e-12)


def test_pid_step_against_plain_loop(rng):
    pid = PositionPidParams(kp_v_per_m=900.0, ki_v_per_m_per_s=2500.0, kd_v_s_per_m=3.0,
                            derivative_filter_hz=150.0, output_limit_v=2.0)
    c = pid_coefficients(pid, DT)
    y = np.cumsum(rng.normal(0, 1e-4, 400))
    r = np.full(400, 0.003)
    st = CK.PidState(integral_v=0.0, derivative_v=0.0, measurement_prev=y[0])
    tau = 1 / (2 * math.pi * pid.derivative_filter_hz)
    integ = deriv = 0.0
    for k in range(400):
        e = r[k] - y[k]
        u, st = CK.pid_step(e, y[k], st, c)
        deriv = tau / (tau + DT) * deriv - pid.kd_v_s_per_m / (tau + DT) * (
            y[k] - (y[k - 1] if k else y[0]))
        ref = pid.kp_v_per_m * e + integ + deriv
        if not ((ref > 2.0 and e > 0) or (ref < -2.0 and e < 0)):
            integ += pid.ki_v_per_m_per_s * e * DT
        assert_allclose(u, ref, rtol=1e-12, atol=1e-14)


def test_tvc_generator_in_the_step():
    tvc = TvcParams(kg=1.0, generator_omega_rad_s=3.14, generator_damping=0.7,
                    kdf_v_per_m=1.0, kvf_v_per_m_s=0.0, kaf_v_per_m_s2=0.0, kdr=1.0,
                    kvr_s=0.0, kar_s2=0.0)
    c = tvc_coefficients(tvc, DT)
    st = CK.TvcState(0.0, 0.0, 0.0, 0.0, 0.0)
    # ym = am = 0: u = Kdf Kdr r_d, the ZOH step response of GAR, settling to Kg/δg
    out = np.empty(20000)
    for k in range(out.size):
        out[k], _, st = CK.tvc_step(1.0, 0.0, 0.0, st, c)
    sys = scipy.signal.StateSpace([[0, 1], [-3.14**2, -2 * 0.7 * 3.14]], [[0], [1.0]],
                                  [[1, 0]], [[0]])
    _, y_ref = scipy.signal.step(sys, T=np.arange(20000) * DT)
    assert_allclose(out, y_ref, rtol=1e-6, atol=1e-9)  # lsim's own integration accuracy
    assert_allclose(out[-1], 1 / 3.14**2, rtol=1e-6)
