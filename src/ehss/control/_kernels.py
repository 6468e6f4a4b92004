"""Numba kernels of the digital controllers of the three loops (one step each).

The settings are NamedTuples of discrete coefficients built by
:mod:`ehss.control.discrete` (:class:`PidSettings`, :class:`TvcSettings`); a
controller's memory is a NamedTuple too (:class:`PidState`, :class:`TvcState`). A step
takes the state and returns the output with the next state, so it allocates nothing and
a reader sees every variable by name. :mod:`ehss.control.kernels` is the public face of
this module.

Symbol table
------------
==========  ================================  ===========================================
symbol      code                              meaning
==========  ================================  ===========================================
e, y_m      e, ym                             error and measured (fed-back) variable
I, D        integral_v, derivative_v          PID integral and filtered derivative terms
τ           (in derivative_pole, _gain)       derivative filter time constant
r_d, v_d    rd_m, vd_m_s                      generated displacement and velocity, eq (10)
a_d         ad                                generated acceleration, eq (10)
v̂           v_hat_m_s                         synthesised velocity (Fig. 6)
Φ, Γ        phi_*, gamma_*                    ZOH discretisation of the generator
==========  ================================  ===========================================
"""

from __future__ import annotations

from typing import NamedTuple

from numba import njit

__all__ = [
    "PidSettings",
    "PidState",
    "TvcSettings",
    "TvcState",
    "pid_step",
    "tvc_step",
]


class PidSettings(NamedTuple):
    """Discrete coefficients of a PID (eq (9) position, eq (15) force)."""

    kp: float  # proportional gain, V per m or V per N
    ki_dt: float  # ki·dt, integral gain times the control period
    derivative_pole: float  # τ/(τ + dt), backward-Euler pole of the derivative filter
    derivative_gain: float  # kd/(τ + dt)
    output_limit_v: float  # drive clipped to ±output_limit_v


class PidState(NamedTuple):
    """Memory of a PID between two control periods."""

    integral_v: float  # I
    derivative_v: float  # D
    measurement_prev: float  # y_m[k−1]


class TvcSettings(NamedTuple):
    """Discrete coefficients of the three-variable controller (eqs (10)–(12), Fig. 6)."""

    # generator, eq (10): [r_d, v_d][k+1] = Φ [r_d, v_d][k] + Γ a_r[k]  (exact ZOH)
    phi_rr: float  # Φ[0, 0]
    phi_rv: float  # Φ[0, 1], s
    phi_vr: float  # Φ[1, 0], 1/s
    phi_vv: float  # Φ[1, 1]
    gamma_r: float  # Γ[0], s²
    gamma_v: float  # Γ[1], s
    # a_d = Kg a_r − ωg v_d − δg r_d
    kg: float  # Kg
    omega_g_rad_s: float  # ωg = 2 ζn ωn
    delta_g_rad2_s2: float  # δg = ωn²
    # feedback (f) and feed-forward (r) gains, eqs (11)–(12)
    kdf_v_per_m: float
    kvf_v_per_m_s: float
    kaf_v_per_m_s2: float
    kdr: float
    kvr_s: float
    kar_s2: float
    # complementary velocity filter v̂ = (ωc s y + a)/(s + ωc), Tustin with c = 2/dt
    vf_pole: float  # (c − ωc)/(c + ωc)
    vf_gain_y_1_s: float  # ωc c/(c + ωc)
    vf_gain_a_s: float  # 1/(c + ωc)
    output_limit_v: float  # drive clipped to ±output_limit_v


class TvcState(NamedTuple):
    """Memory of the three-variable controller between two control periods."""

    rd_m: float  # r_d[k], generated displacement
    vd_m_s: float  # v_d[k], generated velocity
    v_hat_m_s: float  # v̂[k−1]
    y_prev_m: float  # y[k−1], LVDT
    a_prev_m_s2: float  # a[k−1], accelerometer


@njit(cache=True)
def pid_step(e: float, ym: float, st: PidState, c: PidSettings) -> tuple[float, PidState]:
    """One PID step; returns the unsaturated output and the next :class:`PidState`.

    u = kp e + I + D, derivative on measurement with a first-order filter (backward Euler),
    conditional integration as anti-windup.
    """
    # D[k] = τ/(τ+dt) D[k−1] − kd/(τ+dt) (y_m[k] − y_m[k−1])
    d = c.derivative_pole * st.derivative_v - c.derivative_gain * (ym - st.measurement_prev)
    # u = kp e + I + D   (I from the previous periods)
    u = c.kp * e + st.integral_v + d
    # I += ki e dt, skipped while saturated and e pushes further into saturation
    lim = c.output_limit_v
    integral = st.integral_v
    if not ((u > lim and e > 0.0) or (u < -lim and e < 0.0)):
        integral += c.ki_dt * e
    return u, PidState(integral_v=integral, derivative_v=d, measurement_prev=ym)


@njit(cache=True)
def tvc_step(ar: float, ym: float, am: float, st: TvcState,
             c: TvcSettings) -> tuple[float, float, TvcState]:
    """One three-variable-controller step (eqs (10)–(12), Fig. 6).

    ``ar`` acceleration reference, ``ym`` LVDT, ``am`` accelerometer. Returns the
    unsaturated output, the generated acceleration a_d of this period and the next
    :class:`TvcState`.
    """
    rd = st.rd_m
    vd = st.vd_m_s
    # a_d = Kg a_r − ωg v_d − δg r_d            (generator, eq (10))
    ad = c.kg * ar - c.omega_g_rad_s * vd - c.delta_g_rad2_s2 * rd
    # v̂ = (ωc s y + a)/(s + ωc), Tustin:
    # v̂[k] = p v̂[k−1] + ωc c/(c+ωc) (y[k] − y[k−1]) + (a[k] + a[k−1])/(c+ωc)
    vh = (
        c.vf_pole * st.v_hat_m_s
        + c.vf_gain_y_1_s * (ym - st.y_prev_m)
        + c.vf_gain_a_s * (am + st.a_prev_m_s2)
    )
    # u = Kdf (Kdr r_d + Kvr v_d + Kar a_d − y) − Kvf v̂ − Kaf a   (eq (12) feed-forward)
    u = (
        c.kdf_v_per_m * (c.kdr * rd + c.kvr_s * vd + c.kar_s2 * ad - ym)
        - c.kvf_v_per_m_s * vh
        - c.kaf_v_per_m_s2 * am
    )
    # [r_d, v_d][k+1] = Φ [r_d, v_d][k] + Γ a_r[k]   (exact ZOH discretisation)
    nxt = TvcState(
        rd_m=c.phi_rr * rd + c.phi_rv * vd + c.gamma_r * ar,
        vd_m_s=c.phi_vr * rd + c.phi_vv * vd + c.gamma_v * ar,
        v_hat_m_s=vh,
        y_prev_m=ym,
        a_prev_m_s2=am,
    )
    return u, ad, nxt
