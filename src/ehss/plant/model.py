"""Nonlinear model of one actuator channel: parameter packing and operating points.

The equations are those of PAPER.md §2 (eqs (1), (2)–(6)) with the realistic effects of
§7; they are written out in :mod:`ehss.plant._kernels`. This module turns a
:class:`~ehss.params.RigParams` into the kernels' parameter vector and finds steady
operating points (e.g. a static force on the specimen).

Modelling choices that the parameter set does not fix
----------------------------------------------------
* Orifice root: a laminar region of width ``LAMINAR_DP_FRACTION``·Δp_r around a zero
  land drop (only reached near the pressure limits, never at small amplitude).
* Pressure limits: the state is clamped to [0, Ps] after every integration step (hard
  clamp, not a soft one).
* Friction sign: tanh(v/v_eps) with v_eps chosen so that the friction slope
  (Fc + Fs)/v_eps stays resolvable by the integrator: v_eps = max(1e-5 m/s,
  2 (Fc + Fs) h / m), h the internal step, m the mass the friction acts on.
* Joint clearance: the rod carries ``ROD_MASS_FRACTION`` of mt and meets the table
  through a spring-damper (natural frequency ``JOINT_OMEGA_STEP``/h, damping ratio 0.5 on
  the reduced mass) outside the dead zone ±clearance/2. Without clearance one body.
* Stroke ends: a spring-damper beyond ±stroke (natural frequency 0.5/h with mt,
  damping ratio 0.5).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from ehss.errors import ParameterError
from ehss.params import RigParams
from ehss.plant import _kernels as K

__all__ = [
    "STATE_NAMES",
    "LAMINAR_DP_FRACTION",
    "ROD_MASS_FRACTION",
    "plant_parameter_vector",
    "rest_state",
    "static_force_state",
    "apply_initial_state",
]

#: Names of the plant state vector, in kernel order (see :mod:`ehss.plant._kernels`).
STATE_NAMES = (
    "spool",
    "spool_rate_1_s",
    "piston_displacement_m",
    "piston_velocity_m_s",
    "p1_pa",
    "p2_pa",
    "displacement_m",
    "velocity_m_s",
    "accel_highpass_state_m_s",
)
LAMINAR_DP_FRACTION = 1e-3
ROD_MASS_FRACTION = 0.1
JOINT_OMEGA_STEP = 0.5
STOP_OMEGA_STEP = 0.5


def plant_parameter_vector(
    params: RigParams,
    *,
    stiffness_n_m: float,
    internal_dt_s: float,
    spool_direct: bool = False,
) -> np.ndarray:
    """Pack ``params`` into the kernel parameter vector (layout ``P_*``).

    Parameters
    ----------
    params : RigParams
    stiffness_n_m : float
        K of eq (6) for this test (load.stiffness_n_m, or the specimen stiffness in the
        force loop).
    internal_dt_s : float
        Integration step h, used to size the stiff contact and friction terms.
    spool_direct : bool
        The spool position is prescribed (open-loop tests) instead of integrated.

    Returns
    -------
    ndarray, shape (N_PRM,)
    """
    v, a, ld, s = params.valve, params.actuator, params.load, params.sensors
    h = internal_dt_s
    p = np.zeros(K.N_PRM)
    p[K.P_OMEGA_V] = v.omega_rad_s
    p[K.P_ZETA_V] = v.damping
    p[K.P_SATURATE] = 1.0 if v.saturate else 0.0
    p[K.P_DEADBAND] = v.deadband
    # Q = Qr |u| √(Δp_land / (Δp_r/2)): the rated drop is shared by two lands
    p[K.P_FLOW_COEF] = v.rated_flow_m3_s / math.sqrt(0.5 * v.rated_pressure_drop_pa)
    p[K.P_DP_LAMINAR] = LAMINAR_DP_FRACTION * v.rated_pressure_drop_pa
    p[K.P_KC] = v.null_leakage_m3_s_pa
    p[K.P_AP] = a.piston_area_m2
    p[K.P_VT] = a.total_volume_m3
    p[K.P_BETA] = a.bulk_modulus_pa
    p[K.P_PS] = a.supply_pressure_pa
    p[K.P_PR] = a.return_pressure_pa
    p[K.P_CIP] = a.internal_leakage_m3_s_pa
    p[K.P_CEP] = a.external_leakage_m3_s_pa
    mt = ld.mass_kg
    if ld.clearance_m > 0.0:
        m_rod = ROD_MASS_FRACTION * mt
        m_table = mt - m_rod
        m_red = m_rod * m_table / mt
        w_joint = JOINT_OMEGA_STEP / h
        p[K.P_KJ] = m_red * w_joint**2
        p[K.P_CJ] = 2.0 * 0.5 * math.sqrt(p[K.P_KJ] * m_red)
    else:
        m_rod, m_table = mt, mt
    p[K.P_MASS_ROD] = m_rod
    p[K.P_MASS_TABLE] = m_table
    p[K.P_CLEARANCE] = ld.clearance_m
    p[K.P_BP] = ld.damping_n_s_m
    p[K.P_K] = stiffness_n_m
    p[K.P_FC] = ld.coulomb_friction_n
    p[K.P_FS] = ld.stribeck_friction_n
    p[K.P_VS] = ld.stribeck_velocity_m_s
    p[K.P_VEPS] = max(1e-5, 2.0 * (ld.coulomb_friction_n + ld.stribeck_friction_n) * h / m_rod)
    p[K.P_STROKE] = a.stroke_m
    w_stop = STOP_OMEGA_STEP / h
    p[K.P_KSTOP] = m_rod * w_stop**2
    p[K.P_CSTOP] = 2.0 * 0.5 * math.sqrt(p[K.P_KSTOP] * m_rod)
    p[K.P_OMEGA_HP] = 2.0 * math.pi * s.accel_highpass_hz
    p[K.P_SPOOL_DIRECT] = 1.0 if spool_direct else 0.0
    return p


def rest_state(params: RigParams) -> np.ndarray:
    """Plant at rest, mid-stroke, both chambers at (Ps + Pr)/2 (shape (N_STATE,))."""
    a = params.actuator
    x = np.zeros(K.N_STATE)
    pc = 0.5 * (a.supply_pressure_pa + a.return_pressure_pa)
    x[K.X_P1] = pc
    x[K.X_P2] = pc
    x[K.X_SPOOL] = params.valve.null_bias
    return x


def static_force_state(
    params: RigParams, force_n: float, prm: np.ndarray
) -> tuple[np.ndarray, float]:
    """Steady state holding ``force_n`` against the stiffness in ``prm`` (eq (6) at rest).

    Solves Ṗ1 = Ṗ2 = 0 for the spool opening and the common-mode pressure with
    y = F/K, v = 0, Ap PL = F. Returns the state and the valve command in volts that holds
    it (the spool opening that makes up for the leakage, minus the null bias).

    Raises
    ------
    ParameterError
        If the force cannot be held (K = 0, outside the stroke or beyond Ap (Ps − Pr)).
    """
    import scipy.optimize

    a = params.actuator
    k = prm[K.P_K]
    x = rest_state(params)
    # Forces far below the load cell's resolution are rest: the root finder cannot resolve
    # the spool opening for them (the orifice's laminar region dominates), and need not.
    if abs(force_n) <= 1e-9 * params.max_actuator_force_n:
        return x, -params.valve.null_bias * params.valve.command_full_scale_v
    if k <= 0.0:
        raise ParameterError("a static force needs a stiffness K > 0 in eq (6)")
    y0 = force_n / k
    if abs(y0) >= a.stroke_m:
        raise ParameterError(
            f"a static force of {force_n:.6g} N on K={k:.6g} N/m needs y={y0:.6g} m, "
            f"outside the stroke ±{a.stroke_m} m"
        )
    pl = force_n / a.piston_area_m2
    if abs(pl) >= a.supply_pressure_pa - a.return_pressure_pa:
        raise ParameterError(
            f"a static force of {force_n:.6g} N exceeds the stall force "
            f"{params.max_actuator_force_n:.6g} N"
        )
    x[K.X_POS] = y0
    x[K.X_TABLE_POS] = y0
    pc0 = 0.5 * (a.supply_pressure_pa + a.return_pressure_pa)
    deriv = K.plant_derivative.py_func
    prm_direct = prm.copy()
    prm_direct[K.P_SPOOL_DIRECT] = 1.0
    dx = np.zeros(K.N_STATE)
    scale = a.supply_pressure_pa

    def residual(z: np.ndarray) -> np.ndarray:
        xs = x.copy()
        xs[K.X_SPOOL] = z[0]
        xs[K.X_P1] = pc0 + z[1] * scale + 0.5 * pl
        xs[K.X_P2] = pc0 + z[1] * scale - 0.5 * pl
        deriv(xs, 0.0, prm_direct, dx)
        return np.array([dx[K.X_P1], dx[K.X_P2]]) / a.bulk_modulus_pa

    u_guess = params.kce_m3_s_pa * pl / params.flow_gain_m3_s
    sol = scipy.optimize.root(residual, np.array([u_guess, 0.0]), method="hybr", tol=1e-14)
    u0, dpc = float(sol.x[0]), float(sol.x[1])
    # judged by the residual (|Ṗ| below ~1 kPa/s), not by the solver's progress flag
    if not np.max(np.abs(sol.fun)) < 1e-12 or abs(u0) >= 1.0:  # pragma: no cover
        raise ParameterError(f"no steady state holds a static force of {force_n:.6g} N")
    x[K.X_SPOOL] = u0
    x[K.X_P1] = pc0 + dpc * scale + 0.5 * pl
    x[K.X_P2] = pc0 + dpc * scale - 0.5 * pl
    drive_v = (u0 - params.valve.null_bias) * params.valve.command_full_scale_v
    return x, drive_v


def apply_initial_state(x: np.ndarray, initial_state: Mapping[str, float] | None) -> np.ndarray:
    """Override entries of the state vector ``x`` by name (see :data:`STATE_NAMES`).

    Setting ``displacement_m``/``velocity_m_s`` also sets the piston (rigid joint), unless
    the piston values are given too.

    Raises
    ------
    ParameterError
        For an unknown name or a non-finite value.
    """
    if not initial_state:
        return x
    x = x.copy()
    for name, value in initial_state.items():
        if name not in STATE_NAMES:
            raise ParameterError(f"unknown initial state {name!r}; known: {list(STATE_NAMES)}")
        value = float(value)
        if not math.isfinite(value):
            raise ParameterError(f"initial state {name}={value!r} must be finite")
        x[STATE_NAMES.index(name)] = value
    for table, piston in (("displacement_m", "piston_displacement_m"),
                          ("velocity_m_s", "piston_velocity_m_s")):
        if table in initial_state and piston not in initial_state:
            x[STATE_NAMES.index(piston)] = x[STATE_NAMES.index(table)]
        elif piston in initial_state and table not in initial_state:
            x[STATE_NAMES.index(table)] = x[STATE_NAMES.index(piston)]
    return x
