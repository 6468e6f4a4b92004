"""Slow, obvious references of the plant and controller kernels (plain Python, no numba).

Written from the equations (PAPER.md §2, §5, §7) and the RigParams fields directly, not
from the kernels' settings, so that a packing mistake shows up too.
"""

from __future__ import annotations

import math

import numpy as np

from ehss.params import RigParams
from ehss.plant.model import JOINT_OMEGA_STEP, LAMINAR_DP_FRACTION, ROD_MASS_FRACTION


def derivative(x, u_cmd, p: RigParams, *, k_n_m: float, h: float, spool_direct=False):
    """ẋ for state [u, u̇, y, v, P1, P2, yt, vt, z]."""
    v_, a_, ld = p.valve, p.actuator, p.load
    u, du, y, v, p1, p2, yt, vt, z = (float(e) for e in x)
    dx = np.zeros(9)
    if not spool_direct:
        wv = 2 * math.pi * v_.natural_freq_hz
        dx[0] = du
        dx[1] = wv**2 * (u_cmd - u) - 2 * v_.damping * wv * du
    if v_.saturate:
        u = min(1.0, max(-1.0, u))
    if abs(u) <= v_.deadband:
        u = 0.0
    else:
        u = u - math.copysign(v_.deadband, u)
    lam = LAMINAR_DP_FRACTION * v_.rated_pressure_drop_pa

    def land(dp):  # Qr |u| √(Δp/(Δp_r/2)) with the signed laminar root
        return v_.rated_flow_m3_s * dp / math.sqrt(abs(dp) + lam) / math.sqrt(
            v_.rated_pressure_drop_pa / 2
        )

    ps, pr = a_.supply_pressure_pa, a_.return_pressure_pa
    if u >= 0:
        q1, q2 = u * land(ps - p1), u * land(p2 - pr)
    else:
        q1, q2 = u * land(p1 - pr), u * land(ps - p2)
    kc = v_.null_leakage_m3_s_pa
    q1 += kc * (ps - p1) - kc * (p1 - pr)
    q2 += -kc * (ps - p2) + kc * (p2 - pr)

    fsum = ld.coulomb_friction_n + ld.stribeck_friction_n
    mt = ld.mass_kg
    m_rod = ROD_MASS_FRACTION * mt if ld.clearance_m > 0 else mt
    if fsum > 0:
        v_eps = max(1e-5, 2 * fsum * h / m_rod)
        stribeck = math.exp(-((v / ld.stribeck_velocity_m_s) ** 2))
        ff = math.tanh(v / v_eps) * (ld.coulomb_friction_n + ld.stribeck_friction_n * stribeck)
    else:
        ff = 0.0
    ap = a_.piston_area_m2
    pl = p1 - p2
    assert abs(y) <= a_.stroke_m  # end stops not modelled in this reference
    if ld.clearance_m == 0:
        acc = (ap * pl - ld.damping_n_s_m * v - k_n_m * y - ff) / mt
        dx[2:4] = v, acc
        dx[6:8] = v, acc
        a_table = acc
    else:
        m_tab = mt - m_rod
        m_red = m_rod * m_tab / mt
        kj = m_red * (JOINT_OMEGA_STEP / h) ** 2
        cj = math.sqrt(kj * m_red)
        gap, half = y - yt, ld.clearance_m / 2
        fj = 0.0 if abs(gap) <= half else kj * (gap - math.copysign(half, gap)) + cj * (v - vt)
        dx[2:4] = v, (ap * pl - ff - fj) / m_rod
        a_table = (fj - ld.damping_n_s_m * vt - k_n_m * yt) / m_tab
        dx[6:8] = vt, a_table
    be, vt_ = a_.bulk_modulus_pa, a_.total_volume_m3
    cip, cep = a_.internal_leakage_m3_s_pa, a_.external_leakage_m3_s_pa
    dx[4] = be / (vt_ / 2 + ap * y) * (q1 - ap * v - cip * pl - cep * p1)
    dx[5] = be / (vt_ / 2 - ap * y) * (-q2 + ap * v + cip * pl - cep * p2)
    dx[8] = a_table - 2 * math.pi * p.sensors.accel_highpass_hz * z
    return dx


def rk4(x, u_cmd, p, *, k_n_m, h, spool_direct=False):
    """One classical RK4 step followed by the pressure and spool clamps."""
    x = np.asarray(x, float)

    def f(s):
        return derivative(s, u_cmd, p, k_n_m=k_n_m, h=h, spool_direct=spool_direct)

    k1 = f(x)
    k2 = f(x + h / 2 * k1)
    k3 = f(x + h / 2 * k2)
    k4 = f(x + h * k3)
    x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    ps = p.actuator.supply_pressure_pa
    x[4] = min(ps, max(0.0, x[4]))
    x[5] = min(ps, max(0.0, x[5]))
    if p.valve.saturate and abs(x[0]) > 1:
        x[0] = math.copysign(1.0, x[0])
        if x[1] * x[0] > 0:
            x[1] = 0.0
    return x
