"""Numba kernels of the nonlinear actuator channel (PAPER.md §2 and §7).

Everything here is private: the kernels take only contiguous float64 arrays, scalars and
preallocated outputs and do no validation. :mod:`ehss.plant.model` packs a
:class:`~ehss.params.RigParams` into the parameter vector ``prm`` whose layout is given by
the ``P_*`` indices below.

Symbol table
------------
State vector ``x`` (``X_*`` indices)::

    u, u̇        normalised spool position and rate, eq (1)
    y, v        piston (rod) displacement and velocity, m and m/s
    P1, P2      chamber pressures, Pa
    yt, vt      table (load) displacement and velocity; equal to y, v without clearance
    z           state of the accelerometer's AC coupling (first-order high-pass)

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

import numpy as np
from numba import njit

__all__ = [
    "N_STATE",
    "N_PRM",
    "signed_sqrt",
    "friction_force",
    "plant_derivative",
    "rk4_step",
    "clamp_state",
    "adc",
]

# ----------------------------------------------------------------- state indices
X_SPOOL = 0
X_SPOOL_RATE = 1
X_POS = 2
X_VEL = 3
X_P1 = 4
X_P2 = 5
X_TABLE_POS = 6
X_TABLE_VEL = 7
X_HP = 8
N_STATE = 9

# ----------------------------------------------------------------- parameter indices
P_OMEGA_V = 0  # ωv, rad/s
P_ZETA_V = 1  # ζv
P_SATURATE = 2  # 1.0: spool limited to [−1, 1]
P_DEADBAND = 3  # overlap, fraction of full spool
P_FLOW_COEF = 4  # Qr / √(Δp_r/2), m³/(s·√Pa) per unit spool and land
P_DP_LAMINAR = 5  # Δp_lam of the signed root, Pa
P_KC = 6  # Kc, laminar null leakage per land, m³/(s·Pa)
P_AP = 7  # Ap, m²
P_VT = 8  # Vt, m³
P_BETA = 9  # βe, Pa
P_PS = 10  # Ps, Pa
P_PR = 11  # Pr, Pa
P_CIP = 12  # Cip, m³/(s·Pa)
P_CEP = 13  # Cep, m³/(s·Pa)
P_MASS_ROD = 14  # rod mass (mt when there is no clearance), kg
P_MASS_TABLE = 15  # table mass (ignored when there is no clearance), kg
P_BP = 16  # Bp, N·s/m
P_K = 17  # K of eq (6), N/m
P_FC = 18  # Coulomb friction, N
P_FS = 19  # Stribeck friction, N
P_VS = 20  # Stribeck velocity, m/s
P_VEPS = 21  # velocity scale of the smooth sign tanh(v/v_eps), m/s
P_CLEARANCE = 22  # total joint clearance, m (0: rigid joint, one body)
P_KJ = 23  # joint contact stiffness, N/m
P_CJ = 24  # joint contact damping, N·s/m
P_STROKE = 25  # half stroke, m
P_KSTOP = 26  # end-stop stiffness, N/m
P_CSTOP = 27  # end-stop damping, N·s/m
P_OMEGA_HP = 28  # accelerometer AC-coupling corner, rad/s (0: DC coupled)
P_SPOOL_DIRECT = 29  # 1.0: the spool is prescribed (open-loop tests), not integrated
N_PRM = 30


@njit(cache=True)
def signed_sqrt(dp, dp_lam):
    """Sign-preserving root with a laminar region: Δp / √(|Δp| + Δp_lam).

    Turbulent (≈ sgn(Δp) √|Δp|, relative error Δp_lam/(2|Δp|)) for |Δp| ≫ Δp_lam,
    laminar (≈ Δp/√Δp_lam) near 0, continuously differentiable everywhere.
    """
    return dp / np.sqrt(abs(dp) + dp_lam)


@njit(cache=True)
def friction_force(v, prm):
    """Coulomb + Stribeck seal friction with a smooth sign (0 when both levels are 0).

    F = tanh(v/v_eps) [Fc + Fs exp(−(v/vs)²)]
    """
    fc = prm[P_FC]
    fs = prm[P_FS]
    if fc == 0.0 and fs == 0.0:
        return 0.0
    r = v / prm[P_VS]
    return np.tanh(v / prm[P_VEPS]) * (fc + fs * np.exp(-r * r))


@njit(cache=True)
def plant_derivative(x, ucmd, prm, dx):
    """Right-hand side ẋ = f(x, u_cmd) of one actuator channel; writes ``dx``.

    ``ucmd`` is the normalised valve command (V/command_full_scale_v + null bias).
    """
    # ---------------------------------------------------------------- servo valve, eq (1)
    if prm[P_SPOOL_DIRECT] != 0.0:
        dx[X_SPOOL] = 0.0
        dx[X_SPOOL_RATE] = 0.0
    else:
        wv = prm[P_OMEGA_V]
        # ü = ωv² (u_cmd − u) − 2 ζv ωv u̇
        dx[X_SPOOL] = x[X_SPOOL_RATE]
        dx[X_SPOOL_RATE] = wv * wv * (ucmd - x[X_SPOOL]) - 2.0 * prm[P_ZETA_V] * wv * x[
            X_SPOOL_RATE
        ]
    u = x[X_SPOOL]
    if prm[P_SATURATE] != 0.0:
        u = min(1.0, max(-1.0, u))
    # overlap: no opening inside ±deadband, opening shifted by the deadband outside it
    db = prm[P_DEADBAND]
    if db > 0.0:
        if u > db:
            u -= db
        elif u < -db:
            u += db
        else:
            u = 0.0

    # ---------------------------------------------------------------- orifice flows, §5
    p1 = x[X_P1]
    p2 = x[X_P2]
    ps = prm[P_PS]
    pr = prm[P_PR]
    g = prm[P_FLOW_COEF]
    lam = prm[P_DP_LAMINAR]
    if u >= 0.0:
        # Q = Qr u √(Δp_land/(Δp_r/2)): supply → chamber 1, chamber 2 → return
        q1 = g * u * signed_sqrt(ps - p1, lam)
        q2 = g * u * signed_sqrt(p2 - pr, lam)
    else:
        # mirrored: chamber 1 → return, supply → chamber 2 (u < 0 makes both negative)
        q1 = g * u * signed_sqrt(p1 - pr, lam)
        q2 = g * u * signed_sqrt(ps - p2, lam)
    kc = prm[P_KC]
    # laminar null leakage of both lands of each chamber: QL = −Kc PL at null, eq (2)
    q1 += kc * (ps - p1) - kc * (p1 - pr)
    q2 -= kc * (ps - p2) - kc * (p2 - pr)

    # ---------------------------------------------------------------- mechanics, eq (6)
    ap = prm[P_AP]
    y = x[X_POS]
    v = x[X_VEL]
    pl = p1 - p2
    ff = friction_force(v, prm)
    stroke = prm[P_STROKE]
    fstop = 0.0
    if y > stroke:
        fstop = prm[P_KSTOP] * (y - stroke) + prm[P_CSTOP] * v
    elif y < -stroke:
        fstop = prm[P_KSTOP] * (y + stroke) + prm[P_CSTOP] * v
    clearance = prm[P_CLEARANCE]
    if clearance == 0.0:
        # mt ÿ = Ap PL − Bp ẏ − K y − Ff − Fstop ; the table moves with the rod
        a = (ap * pl - prm[P_BP] * v - prm[P_K] * y - ff - fstop) / prm[P_MASS_ROD]
        dx[X_POS] = v
        dx[X_VEL] = a
        dx[X_TABLE_POS] = v
        dx[X_TABLE_VEL] = a
        a_table = a
    else:
        yt = x[X_TABLE_POS]
        vt = x[X_TABLE_VEL]
        gap = y - yt
        half = 0.5 * clearance
        # joint force: stiff spring-damper outside the dead zone ±clearance/2
        fj = 0.0
        if gap > half:
            fj = prm[P_KJ] * (gap - half) + prm[P_CJ] * (v - vt)
        elif gap < -half:
            fj = prm[P_KJ] * (gap + half) + prm[P_CJ] * (v - vt)
        # m_rod ÿ = Ap PL − Ff − Fstop − Fj ; m_table ÿt = Fj − Bp ẏt − K yt
        dx[X_POS] = v
        dx[X_VEL] = (ap * pl - ff - fstop - fj) / prm[P_MASS_ROD]
        a_table = (fj - prm[P_BP] * vt - prm[P_K] * yt) / prm[P_MASS_TABLE]
        dx[X_TABLE_POS] = vt
        dx[X_TABLE_VEL] = a_table

    # ---------------------------------------------------------------- chambers, eq (5)
    beta = prm[P_BETA]
    half_vt = 0.5 * prm[P_VT]
    leak_in = prm[P_CIP] * pl
    cep = prm[P_CEP]
    # Ṗ1 = βe/(Vt/2 + Ap y) (Q1 − Ap ẏ − Cip PL − Cep P1)
    dx[X_P1] = beta / (half_vt + ap * y) * (q1 - ap * v - leak_in - cep * p1)
    # Ṗ2 = βe/(Vt/2 − Ap y) (−Q2 + Ap ẏ + Cip PL − Cep P2)
    dx[X_P2] = beta / (half_vt - ap * y) * (-q2 + ap * v + leak_in - cep * p2)

    # ---------------------------------------------------------------- accelerometer AC coupling
    # a_hp = a − ωa z with ż = a − ωa z  ⇔  a_hp = s/(s + ωa) a
    dx[X_HP] = a_table - prm[P_OMEGA_HP] * x[X_HP]


@njit(cache=True)
def rk4_step(x, ucmd, prm, h, work):
    """One classical Runge-Kutta step of length ``h`` in place; ``work`` is (5, N_STATE)."""
    k1 = work[0]
    k2 = work[1]
    k3 = work[2]
    k4 = work[3]
    xt = work[4]
    n = x.shape[0]
    plant_derivative(x, ucmd, prm, k1)
    for i in range(n):
        xt[i] = x[i] + 0.5 * h * k1[i]
    plant_derivative(xt, ucmd, prm, k2)
    for i in range(n):
        xt[i] = x[i] + 0.5 * h * k2[i]
    plant_derivative(xt, ucmd, prm, k3)
    for i in range(n):
        xt[i] = x[i] + h * k3[i]
    plant_derivative(xt, ucmd, prm, k4)
    # x ← x + h/6 (k1 + 2 k2 + 2 k3 + k4)
    for i in range(n):
        x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])


@njit(cache=True)
def clamp_state(x, prm):
    """Hard limits applied to the state after each step.

    Pressures are clamped to [0, Ps] (cavitation / relief); the spool, if saturating, to
    [−1, 1] with its rate zeroed when it pushes outward (the spool hits its end stop).
    """
    ps = prm[P_PS]
    x[X_P1] = min(ps, max(0.0, x[X_P1]))
    x[X_P2] = min(ps, max(0.0, x[X_P2]))
    if prm[P_SATURATE] != 0.0:
        if x[X_SPOOL] > 1.0:
            x[X_SPOOL] = 1.0
            if x[X_SPOOL_RATE] > 0.0:
                x[X_SPOOL_RATE] = 0.0
        elif x[X_SPOOL] < -1.0:
            x[X_SPOOL] = -1.0
            if x[X_SPOOL_RATE] < 0.0:
                x[X_SPOOL_RATE] = 0.0


@njit(cache=True)
def adc(value, full_scale, lsb):
    """Quantise to a step ``lsb`` and clip to ±``full_scale`` (``lsb`` = 0: pass through)."""
    if lsb <= 0.0:
        return value
    q = np.round(value / lsb) * lsb
    return min(full_scale, max(-full_scale, q))
