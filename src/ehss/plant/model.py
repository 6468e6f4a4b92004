"""Nonlinear model of one actuator channel: parameter packing and operating points.

The equations are those of PAPER.md §2 (eqs (1), (2)–(6)) with the realistic effects of
§7; they are written out in :mod:`ehss.plant._kernels` (public face:
:mod:`ehss.plant.kernels`). This module turns a :class:`~ehss.params.RigParams` into the
kernels' :class:`~ehss.plant.kernels.PlantSettings`, gives the state at rest and finds
steady operating points (e.g. a static force on the specimen).

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
from ehss.plant._kernels import PlantSettings, PlantState, plant_derivative

__all__ = [
    "STATE_NAMES",
    "LAMINAR_DP_FRACTION",
    "ROD_MASS_FRACTION",
    "plant_settings",
    "rest_state",
    "static_force_state",
    "apply_initial_state",
]

#: Names of the plant state, in kernel order (the fields of :class:`PlantState`).
STATE_NAMES = PlantState._fields
LAMINAR_DP_FRACTION = 1e-3
ROD_MASS_FRACTION = 0.1
JOINT_OMEGA_STEP = 0.5
STOP_OMEGA_STEP = 0.5
#: Actuator parameters (eq (5)) the kernels take as they are, under the same names.
_ACTUATOR_AS_GIVEN = ("piston_area_m2", "total_volume_m3", "bulk_modulus_pa",
                      "supply_pressure_pa", "return_pressure_pa", "internal_leakage_m3_s_pa",
                      "external_leakage_m3_s_pa")


def plant_settings(
    params: RigParams,
    *,
    stiffness_n_m: float,
    internal_dt_s: float,
    spool_direct: bool = False,
) -> PlantSettings:
    """Pack ``params`` into the kernels' :class:`~ehss.plant.kernels.PlantSettings`.

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
    PlantSettings
    """
    v, a, ld, s = params.valve, params.actuator, params.load, params.sensors
    h = internal_dt_s
    mt = ld.mass_kg
    joint_stiffness = joint_damping = 0.0
    if ld.clearance_m > 0.0:
        m_rod = ROD_MASS_FRACTION * mt
        m_table = mt - m_rod
        m_red = m_rod * m_table / mt
        w_joint = JOINT_OMEGA_STEP / h
        joint_stiffness = m_red * w_joint**2
        # damping ratio 0.5 on the reduced mass: c = 2 ζ √(k m)
        joint_damping = 2.0 * 0.5 * math.sqrt(joint_stiffness * m_red)
    else:
        m_rod, m_table = mt, mt
    w_stop = STOP_OMEGA_STEP / h
    stop_stiffness = m_rod * w_stop**2
    settings = PlantSettings(
        valve_omega_rad_s=v.omega_rad_s,
        valve_damping=v.damping,
        spool_saturates=bool(v.saturate),
        spool_overlap=v.deadband,
        # Q = Qr |u| √(Δp_land / (Δp_r/2)): the rated drop is shared by two lands
        flow_coef=v.rated_flow_m3_s / math.sqrt(0.5 * v.rated_pressure_drop_pa),
        laminar_dp_pa=LAMINAR_DP_FRACTION * v.rated_pressure_drop_pa,
        null_leakage_m3_s_pa=v.null_leakage_m3_s_pa,
        spool_prescribed=bool(spool_direct),
        **{name: getattr(a, name) for name in _ACTUATOR_AS_GIVEN},
        half_stroke_m=a.stroke_m,
        stop_stiffness_n_m=stop_stiffness,
        stop_damping_n_s_m=2.0 * 0.5 * math.sqrt(stop_stiffness * m_rod),
        rod_mass_kg=m_rod,
        table_mass_kg=m_table,
        damping_n_s_m=ld.damping_n_s_m,
        stiffness_n_m=stiffness_n_m,
        coulomb_friction_n=ld.coulomb_friction_n,
        stribeck_friction_n=ld.stribeck_friction_n,
        stribeck_velocity_m_s=ld.stribeck_velocity_m_s,
        friction_sign_velocity_m_s=max(
            1e-5, 2.0 * (ld.coulomb_friction_n + ld.stribeck_friction_n) * h / m_rod
        ),
        clearance_m=ld.clearance_m,
        joint_stiffness_n_m=joint_stiffness,
        joint_damping_n_s_m=joint_damping,
        accel_highpass_rad_s=2.0 * math.pi * s.accel_highpass_hz,
    )
    # the kernels are compiled for float64 and bool fields, whatever type a value had
    return PlantSettings._make(v if isinstance(v, bool) else float(v) for v in settings)


def rest_state(params: RigParams) -> PlantState:
    """Plant at rest, mid-stroke, both chambers at (Ps + Pr)/2, spool at the null bias."""
    a = params.actuator
    pc = 0.5 * (a.supply_pressure_pa + a.return_pressure_pa)
    return PlantState(
        spool=float(params.valve.null_bias),
        spool_rate_1_s=0.0,
        piston_displacement_m=0.0,
        piston_velocity_m_s=0.0,
        p1_pa=pc,
        p2_pa=pc,
        displacement_m=0.0,
        velocity_m_s=0.0,
        accel_highpass_state_m_s=0.0,
    )


def static_force_state(
    params: RigParams, force_n: float, settings: PlantSettings
) -> tuple[PlantState, float]:
    """Steady state holding ``force_n`` against the stiffness of ``settings`` (eq (6) at rest).

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
    k = settings.stiffness_n_m
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
    pc0 = 0.5 * (a.supply_pressure_pa + a.return_pressure_pa)
    direct = settings._replace(spool_prescribed=True)
    scale = a.supply_pressure_pa

    def held(z: np.ndarray) -> PlantState:
        # spool opening z[0], common-mode pressure shift z[1]·Ps, PL = F/Ap, y = F/K
        return x._replace(
            spool=float(z[0]),
            piston_displacement_m=y0,
            displacement_m=y0,
            p1_pa=pc0 + z[1] * scale + 0.5 * pl,
            p2_pa=pc0 + z[1] * scale - 0.5 * pl,
        )

    def residual(z: np.ndarray) -> np.ndarray:
        dx = plant_derivative(held(z), 0.0, direct)
        return np.array([dx.p1_pa, dx.p2_pa]) / a.bulk_modulus_pa

    u_guess = params.kce_m3_s_pa * pl / params.flow_gain_m3_s
    sol = scipy.optimize.root(residual, np.array([u_guess, 0.0]), method="hybr", tol=1e-14)
    u0 = float(sol.x[0])
    # judged by the residual (|Ṗ| below ~1 kPa/s), not by the solver's progress flag
    if not np.max(np.abs(sol.fun)) < 1e-12 or abs(u0) >= 1.0:  # pragma: no cover
        raise ParameterError(f"no steady state holds a static force of {force_n:.6g} N")
    drive_v = (u0 - params.valve.null_bias) * params.valve.command_full_scale_v
    return held(sol.x), drive_v


def apply_initial_state(
    x: PlantState, initial_state: Mapping[str, float] | None
) -> PlantState:
    """``x`` with the fields named in ``initial_state`` replaced (see :data:`STATE_NAMES`).

    Setting ``displacement_m``/``velocity_m_s`` also sets the piston (rigid joint), unless
    the piston values are given too.

    Raises
    ------
    ParameterError
        For an unknown name or a non-finite value.
    """
    if not initial_state:
        return x
    values: dict[str, float] = {}
    for name, value in initial_state.items():
        if name not in STATE_NAMES:
            raise ParameterError(f"unknown initial state {name!r}; known: {list(STATE_NAMES)}")
        value = float(value)
        if not math.isfinite(value):
            raise ParameterError(f"initial state {name}={value!r} must be finite")
        values[name] = value
    for table, piston in (("displacement_m", "piston_displacement_m"),
                          ("velocity_m_s", "piston_velocity_m_s")):
        if table in values and piston not in values:
            values[piston] = values[table]
        elif piston in values and table not in values:
            values[table] = values[piston]
    return x._replace(**values)
