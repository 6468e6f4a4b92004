"""Numba kernels of the nonlinear actuator channel (PAPER.md §2 and §7).

The kernels take a :class:`PlantSettings` (the rig's constants, packed by
:func:`ehss.plant.model.plant_settings`) and a :class:`PlantState` (the integrated
variables) and do no validation. Both are NamedTuples: inside a kernel every constant
and state variable is read by name, and a step returns a new state instead of writing
into a buffer. :mod:`ehss.plant.kernels` is the public face of this module.

Symbol table
------------
State (:class:`PlantState`)::

    u, u̇        spool, spool_rate_1_s: normalised spool position and rate, eq (1)
    y, v        piston_displacement_m, piston_velocity_m_s: rod, m and m/s
    P1, P2      p1_pa, p2_pa: chamber pressures, Pa
    yt, vt      displacement_m, velocity_m_s: table (load); equal to y, v without clearance
    z           accel_highpass_state_m_s: the accelerometer's AC coupling (high-pass)

Model (the readable equations are repeated before the lines that compute them)::

    ü  = ωv² (u_cmd − u) − 2 ζv ωv u̇                                  eq (1)
    Q1 = Qr u_e sr(Ps − P1)/√(Δp_r/2) + Kc(Ps − P1) − Kc(P1 − Pr)      u_e ≥ 0
    Q2 = Qr u_e sr(P2 − Pr)/√(Δp_r/2) − Kc(Ps − P2) + Kc(P2 − Pr)      (mirrored for u_e < 0)
    Ṗ1 = βe/V1 (Q1 − Ap v − Cip(P1 − P2) − Cep P1),  V1 = Vt/2 + Ap y   eq (5) per chamber
    Ṗ2 = βe/V2 (−Q2 + Ap v + Cip(P1 − P2) − Cep P2), V2 = Vt/2 − Ap y
    mt ÿ = Ap(P1 − P2) − Bp v − K y − Ff(v) − Fstop(y, v)               eq (6)

sr(Δp) = Δp/√(|Δp| + Δp_lam) is a sign-preserving square root with a laminar region of
width Δp_lam around Δp = 0, so the right-hand side stays smooth when a land's pressure
drop reverses. With the joint clearance switched on, the rod (a fraction of mt) and the
table are two bodies joined by a stiff spring-damper with a dead zone of the clearance.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

__all__ = [
    "PlantSettings",
    "PlantState",
    "signed_sqrt",
    "friction_force",
    "plant_derivative",
    "rk4_step",
    "clamp_state",
    "with_spool",
    "adc",
]


class PlantSettings(NamedTuple):
    """Constants of one actuator channel for one test (see :mod:`ehss.plant.model`)."""

    # servo valve, eq (1), and its orifices (§5)
    valve_omega_rad_s: float  # ωv
    valve_damping: float  # ζv
    spool_saturates: bool  # spool limited to [−1, 1]
    spool_overlap: float  # deadband (overlap), fraction of full spool
    flow_coef: float  # Qr / √(Δp_r/2), m³/(s·√Pa) per unit spool and land
    laminar_dp_pa: float  # Δp_lam of the signed root sr
    null_leakage_m3_s_pa: float  # Kc, laminar null leakage per land, eq (2)
    spool_prescribed: bool  # the spool is set from outside (open-loop tests), not integrated
    # actuator, eq (5)
    piston_area_m2: float  # Ap
    total_volume_m3: float  # Vt
    bulk_modulus_pa: float  # βe
    supply_pressure_pa: float  # Ps
    return_pressure_pa: float  # Pr
    internal_leakage_m3_s_pa: float  # Cip
    external_leakage_m3_s_pa: float  # Cep
    half_stroke_m: float  # end stops at ±half_stroke_m
    stop_stiffness_n_m: float  # end-stop spring
    stop_damping_n_s_m: float  # end-stop damper
    # load, eq (6)
    rod_mass_kg: float  # mt when there is no clearance
    table_mass_kg: float  # ignored when there is no clearance
    damping_n_s_m: float  # Bp
    stiffness_n_m: float  # K
    coulomb_friction_n: float  # Fc
    stribeck_friction_n: float  # Fs
    stribeck_velocity_m_s: float  # vs
    friction_sign_velocity_m_s: float  # v_eps of the smooth sign tanh(v/v_eps)
    clearance_m: float  # total joint clearance (0: rigid joint, one body)
    joint_stiffness_n_m: float  # contact stiffness of the joint
    joint_damping_n_s_m: float  # contact damping of the joint
    # accelerometer
    accel_highpass_rad_s: float  # ωa, AC-coupling corner (0: DC coupled)


class PlantState(NamedTuple):
    """State of one actuator channel (also the type of its time derivative)."""

    spool: float  # u, normalised spool position
    spool_rate_1_s: float  # u̇
    piston_displacement_m: float  # y
    piston_velocity_m_s: float  # v
    p1_pa: float  # P1
    p2_pa: float  # P2
    displacement_m: float  # yt, table
    velocity_m_s: float  # vt, table
    accel_highpass_state_m_s: float  # z, accelerometer AC coupling


@njit(cache=True)
def signed_sqrt(dp: float, dp_lam: float) -> float:
    """Sign-preserving root with a laminar region: Δp / √(|Δp| + Δp_lam).

    Turbulent (≈ sgn(Δp) √|Δp|, relative error Δp_lam/(2|Δp|)) for |Δp| ≫ Δp_lam,
    laminar (≈ Δp/√Δp_lam) near 0, continuously differentiable everywhere.
    """
    return dp / np.sqrt(abs(dp) + dp_lam)


@njit(cache=True)
def friction_force(v: float, s: PlantSettings) -> float:
    """Coulomb + Stribeck seal friction with a smooth sign (0 when both levels are 0).

    F = tanh(v/v_eps) [Fc + Fs exp(−(v/vs)²)]
    """
    fc = s.coulomb_friction_n
    fs = s.stribeck_friction_n
    if fc == 0.0 and fs == 0.0:
        return 0.0
    r = v / s.stribeck_velocity_m_s
    return np.tanh(v / s.friction_sign_velocity_m_s) * (fc + fs * np.exp(-r * r))


@njit(cache=True)
def plant_derivative(x: PlantState, ucmd: float, s: PlantSettings) -> PlantState:
    """Right-hand side ẋ = f(x, u_cmd) of one actuator channel, as a :class:`PlantState`.

    ``ucmd`` is the normalised valve command (V/command_full_scale_v + null bias).
    """
    # ---------------------------------------------------------------- servo valve, eq (1)
    if s.spool_prescribed:
        d_spool = 0.0
        d_spool_rate = 0.0
    else:
        wv = s.valve_omega_rad_s
        # ü = ωv² (u_cmd − u) − 2 ζv ωv u̇
        d_spool = x.spool_rate_1_s
        d_spool_rate = wv * wv * (ucmd - x.spool) - 2.0 * s.valve_damping * wv * x.spool_rate_1_s
    # effective opening u_e: the spool within its stops, less the overlap
    u = x.spool
    if s.spool_saturates:
        u = min(1.0, max(-1.0, u))
    # overlap: no opening inside ±deadband, opening shifted by the deadband outside it
    db = s.spool_overlap
    if db > 0.0:
        if u > db:
            u -= db
        elif u < -db:
            u += db
        else:
            u = 0.0

    # ---------------------------------------------------------------- orifice flows, §5
    p1 = x.p1_pa
    p2 = x.p2_pa
    ps = s.supply_pressure_pa
    pr = s.return_pressure_pa
    g = s.flow_coef
    lam = s.laminar_dp_pa
    if u >= 0.0:
        # Q = Qr u √(Δp_land/(Δp_r/2)): supply → chamber 1, chamber 2 → return
        q1 = g * u * signed_sqrt(ps - p1, lam)
        q2 = g * u * signed_sqrt(p2 - pr, lam)
    else:
        # mirrored: chamber 1 → return, supply → chamber 2 (u < 0 makes both negative)
        q1 = g * u * signed_sqrt(p1 - pr, lam)
        q2 = g * u * signed_sqrt(ps - p2, lam)
    kc = s.null_leakage_m3_s_pa
    # laminar null leakage of both lands of each chamber: QL = −Kc PL at null, eq (2)
    q1 += kc * (ps - p1) - kc * (p1 - pr)
    q2 -= kc * (ps - p2) - kc * (p2 - pr)

    # ---------------------------------------------------------------- mechanics, eq (6)
    ap = s.piston_area_m2
    y = x.piston_displacement_m
    v = x.piston_velocity_m_s
    pl = p1 - p2
    ff = friction_force(v, s)
    # end stops: a stiff spring-damper beyond ±half stroke
    stroke = s.half_stroke_m
    fstop = 0.0
    if y > stroke:
        fstop = s.stop_stiffness_n_m * (y - stroke) + s.stop_damping_n_s_m * v
    elif y < -stroke:
        fstop = s.stop_stiffness_n_m * (y + stroke) + s.stop_damping_n_s_m * v
    if s.clearance_m == 0.0:
        # mt ÿ = Ap PL − Bp ẏ − K y − Ff − Fstop ; the table moves with the rod
        a = (ap * pl - s.damping_n_s_m * v - s.stiffness_n_m * y - ff - fstop) / s.rod_mass_kg
        d_table_pos = v
        a_table = a
    else:
        yt = x.displacement_m
        vt = x.velocity_m_s
        gap = y - yt
        half = 0.5 * s.clearance_m
        # joint force: stiff spring-damper outside the dead zone ±clearance/2
        fj = 0.0
        if gap > half:
            fj = s.joint_stiffness_n_m * (gap - half) + s.joint_damping_n_s_m * (v - vt)
        elif gap < -half:
            fj = s.joint_stiffness_n_m * (gap + half) + s.joint_damping_n_s_m * (v - vt)
        # m_rod ÿ = Ap PL − Ff − Fstop − Fj ; m_table ÿt = Fj − Bp ẏt − K yt
        a = (ap * pl - ff - fstop - fj) / s.rod_mass_kg
        d_table_pos = vt
        a_table = (fj - s.damping_n_s_m * vt - s.stiffness_n_m * yt) / s.table_mass_kg

    # ---------------------------------------------------------------- chambers, eq (5)
    beta = s.bulk_modulus_pa
    half_vt = 0.5 * s.total_volume_m3
    leak_in = s.internal_leakage_m3_s_pa * pl
    cep = s.external_leakage_m3_s_pa
    # Ṗ1 = βe/(Vt/2 + Ap y) (Q1 − Ap ẏ − Cip PL − Cep P1)
    d_p1 = beta / (half_vt + ap * y) * (q1 - ap * v - leak_in - cep * p1)
    # Ṗ2 = βe/(Vt/2 − Ap y) (−Q2 + Ap ẏ + Cip PL − Cep P2)
    d_p2 = beta / (half_vt - ap * y) * (-q2 + ap * v + leak_in - cep * p2)

    # ---------------------------------------------------------------- accelerometer AC coupling
    # a_hp = a − ωa z with ż = a − ωa z  ⇔  a_hp = s/(s + ωa) a
    d_hp = a_table - s.accel_highpass_rad_s * x.accel_highpass_state_m_s
    return PlantState(
        spool=d_spool,
        spool_rate_1_s=d_spool_rate,
        piston_displacement_m=v,
        piston_velocity_m_s=a,
        p1_pa=d_p1,
        p2_pa=d_p2,
        displacement_m=d_table_pos,
        velocity_m_s=a_table,
        accel_highpass_state_m_s=d_hp,
    )


# inline="always": folded into rk4_step by numba itself, which compiles faster than
# separate functions that LLVM then inlines
@njit(cache=True, inline="always")
def _add_scaled(x: PlantState, c: float, k: PlantState) -> PlantState:
    """x + c k, field by field (c a scalar, k a derivative)."""
    return PlantState(
        x.spool + c * k.spool,
        x.spool_rate_1_s + c * k.spool_rate_1_s,
        x.piston_displacement_m + c * k.piston_displacement_m,
        x.piston_velocity_m_s + c * k.piston_velocity_m_s,
        x.p1_pa + c * k.p1_pa,
        x.p2_pa + c * k.p2_pa,
        x.displacement_m + c * k.displacement_m,
        x.velocity_m_s + c * k.velocity_m_s,
        x.accel_highpass_state_m_s + c * k.accel_highpass_state_m_s,
    )


@njit(cache=True, inline="always")
def _weighted_slope(k1: PlantState, k2: PlantState, k3: PlantState,
                    k4: PlantState) -> PlantState:
    """k1 + 2 k2 + 2 k3 + k4, field by field."""
    return PlantState(
        k1.spool + 2.0 * k2.spool + 2.0 * k3.spool + k4.spool,
        k1.spool_rate_1_s + 2.0 * k2.spool_rate_1_s + 2.0 * k3.spool_rate_1_s
        + k4.spool_rate_1_s,
        k1.piston_displacement_m + 2.0 * k2.piston_displacement_m
        + 2.0 * k3.piston_displacement_m + k4.piston_displacement_m,
        k1.piston_velocity_m_s + 2.0 * k2.piston_velocity_m_s + 2.0 * k3.piston_velocity_m_s
        + k4.piston_velocity_m_s,
        k1.p1_pa + 2.0 * k2.p1_pa + 2.0 * k3.p1_pa + k4.p1_pa,
        k1.p2_pa + 2.0 * k2.p2_pa + 2.0 * k3.p2_pa + k4.p2_pa,
        k1.displacement_m + 2.0 * k2.displacement_m + 2.0 * k3.displacement_m
        + k4.displacement_m,
        k1.velocity_m_s + 2.0 * k2.velocity_m_s + 2.0 * k3.velocity_m_s + k4.velocity_m_s,
        k1.accel_highpass_state_m_s + 2.0 * k2.accel_highpass_state_m_s
        + 2.0 * k3.accel_highpass_state_m_s + k4.accel_highpass_state_m_s,
    )


@njit(cache=True)
def rk4_step(x: PlantState, ucmd: float, s: PlantSettings, h: float) -> PlantState:
    """One classical Runge-Kutta step of length ``h`` from ``x``; returns the new state."""
    k1 = plant_derivative(x, ucmd, s)
    k2 = plant_derivative(_add_scaled(x, 0.5 * h, k1), ucmd, s)
    k3 = plant_derivative(_add_scaled(x, 0.5 * h, k2), ucmd, s)
    k4 = plant_derivative(_add_scaled(x, h, k3), ucmd, s)
    # x ← x + h/6 (k1 + 2 k2 + 2 k3 + k4)
    return _add_scaled(x, h / 6.0, _weighted_slope(k1, k2, k3, k4))


@njit(cache=True)
def clamp_state(x: PlantState, s: PlantSettings) -> PlantState:
    """``x`` within the hard limits applied after each step.

    Pressures are clamped to [0, Ps] (cavitation / relief); the spool, if saturating, to
    [−1, 1] with its rate zeroed when it pushes outward (the spool hits its end stop).
    """
    ps = s.supply_pressure_pa
    spool = x.spool
    rate = x.spool_rate_1_s
    if s.spool_saturates:
        if spool > 1.0:
            spool = 1.0
            if rate > 0.0:
                rate = 0.0
        elif spool < -1.0:
            spool = -1.0
            if rate < 0.0:
                rate = 0.0
    return _with_valve_and_chambers(x, spool, rate, min(ps, max(0.0, x.p1_pa)),
                                    min(ps, max(0.0, x.p2_pa)))


@njit(cache=True)
def with_spool(x: PlantState, spool: float) -> PlantState:
    """``x`` with the spool set to ``spool`` (a prescribed spool, open-loop tests)."""
    return _with_valve_and_chambers(x, spool, x.spool_rate_1_s, x.p1_pa, x.p2_pa)


@njit(cache=True)
def _with_valve_and_chambers(x: PlantState, spool: float, spool_rate_1_s: float,
                             p1_pa: float, p2_pa: float) -> PlantState:
    """``x`` with new spool, spool rate and chamber pressures, the motion unchanged."""
    return PlantState(
        spool=spool,
        spool_rate_1_s=spool_rate_1_s,
        piston_displacement_m=x.piston_displacement_m,
        piston_velocity_m_s=x.piston_velocity_m_s,
        p1_pa=p1_pa,
        p2_pa=p2_pa,
        displacement_m=x.displacement_m,
        velocity_m_s=x.velocity_m_s,
        accel_highpass_state_m_s=x.accel_highpass_state_m_s,
    )


@njit(cache=True)
def adc(value: float, full_scale: float, lsb: float) -> float:
    """Quantise to a step ``lsb`` and clip to ±``full_scale`` (``lsb`` = 0: pass through)."""
    if lsb <= 0.0:
        return value
    q = np.round(value / lsb) * lsb
    return min(full_scale, max(-full_scale, q))
