"""Numba kernels of the digital controllers of the three loops (one step each).

The coefficient vectors are built by :mod:`ehss.control.discrete`; the layouts are the
``PID_*`` and ``TVC_*`` indices below. Controller states live in small float64 arrays
owned by the caller, so a step allocates nothing.

PID state ``st``: ``[I, D, y_prev]``; TVC state ``st``: ``[r_d, v_d, v̂, y_prev, a_prev]``.
"""

from __future__ import annotations

from numba import njit

__all__ = ["pid_step", "tvc_step", "N_PID", "N_TVC", "N_PID_STATE", "N_TVC_STATE"]

# ----------------------------------------------------------------- PID coefficients
PID_KP = 0  # kp
PID_KI_DT = 1  # ki·dt
PID_D_POLE = 2  # τ/(τ + dt)
PID_D_GAIN = 3  # kd/(τ + dt)
PID_LIMIT = 4  # output limit, V
N_PID = 5
N_PID_STATE = 3

# ----------------------------------------------------------------- TVC coefficients
TVC_PHI00 = 0  # generator ZOH transition matrix Φ (2×2, row major)
TVC_PHI01 = 1
TVC_PHI10 = 2
TVC_PHI11 = 3
TVC_GAM0 = 4  # generator ZOH input vector Γ
TVC_GAM1 = 5
TVC_KG = 6  # Kg
TVC_WG = 7  # ωg = 2 ζn ωn
TVC_DG = 8  # δg = ωn²
TVC_KDF = 9
TVC_KVF = 10
TVC_KAF = 11
TVC_KDR = 12
TVC_KVR = 13
TVC_KAR = 14
TVC_VF_POLE = 15  # (c − ωc)/(c + ωc), c = 2/dt   (Tustin)
TVC_VF_Y = 16  # ωc c/(c + ωc)
TVC_VF_A = 17  # 1/(c + ωc)
TVC_LIMIT = 18
N_TVC = 19
N_TVC_STATE = 5


@njit(cache=True)
def pid_step(e, ym, st, c):
    """One PID step; returns the unsaturated output and updates ``st`` = [I, D, y_prev].

    u = kp e + I + D, derivative on measurement with a first-order filter (backward Euler),
    conditional integration as anti-windup.
    """
    # D[k] = τ/(τ+dt) D[k−1] − kd/(τ+dt) (y_m[k] − y_m[k−1])
    d = c[PID_D_POLE] * st[1] - c[PID_D_GAIN] * (ym - st[2])
    # u = kp e + I + D   (I from the previous periods)
    u = c[PID_KP] * e + st[0] + d
    # I += ki e dt, skipped while saturated and e pushes further into saturation
    lim = c[PID_LIMIT]
    if not ((u > lim and e > 0.0) or (u < -lim and e < 0.0)):
        st[0] += c[PID_KI_DT] * e
    st[1] = d
    st[2] = ym
    return u


@njit(cache=True)
def tvc_step(ar, ym, am, st, c):
    """One three-variable-controller step (eqs (10)–(12), Fig. 6); returns the output.

    ``ar`` acceleration reference, ``ym`` LVDT, ``am`` accelerometer;
    ``st`` = [r_d, v_d, v̂, y_prev, a_prev].
    """
    rd = st[0]
    vd = st[1]
    # a_d = Kg a_r − ωg v_d − δg r_d            (generator, eq (10))
    ad = c[TVC_KG] * ar - c[TVC_WG] * vd - c[TVC_DG] * rd
    # v̂ = (ωc s y + a)/(s + ωc), Tustin:
    # v̂[k] = p v̂[k−1] + ωc c/(c+ωc) (y[k] − y[k−1]) + (a[k] + a[k−1])/(c+ωc)
    vh = c[TVC_VF_POLE] * st[2] + c[TVC_VF_Y] * (ym - st[3]) + c[TVC_VF_A] * (am + st[4])
    # u = Kdf (Kdr r_d + Kvr v_d + Kar a_d − y) − Kvf v̂ − Kaf a   (eq (12) feed-forward)
    u = (
        c[TVC_KDF] * (c[TVC_KDR] * rd + c[TVC_KVR] * vd + c[TVC_KAR] * ad - ym)
        - c[TVC_KVF] * vh
        - c[TVC_KAF] * am
    )
    # [r_d, v_d][k+1] = Φ [r_d, v_d][k] + Γ a_r[k]   (exact ZOH discretisation)
    st[0] = c[TVC_PHI00] * rd + c[TVC_PHI01] * vd + c[TVC_GAM0] * ar
    st[1] = c[TVC_PHI10] * rd + c[TVC_PHI11] * vd + c[TVC_GAM1] * ar
    st[2] = vh
    st[3] = ym
    st[4] = am
    return u
