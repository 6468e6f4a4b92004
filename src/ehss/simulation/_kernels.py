"""The closed-loop simulation in one numba kernel (plant + sensors + controller + delay).

Timing of one control period k (t_k = k dt, dt = 1/fs):

1. sample the sensors on the plant state x(t_k) (noise, ADC quantisation);
2. run the controller → drive[k], clip to ±limit, DAC-quantise;
3. push drive[k] into the delay line; the valve receives drive[k − delay] (held, ZOH);
4. integrate the plant over [t_k, t_{k+1}) with ``n_sub`` RK4 steps.

Everything recorded at index k refers to t_k. No allocation inside the loop.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ehss.control._kernels import TVC_DG, TVC_KG, TVC_WG, pid_step, tvc_step
from ehss.plant._kernels import (
    N_STATE,
    P_AP,
    P_OMEGA_HP,
    P_PS,
    P_SATURATE,
    P_SPOOL_DIRECT,
    P_STROKE,
    X_HP,
    X_P1,
    X_P2,
    X_POS,
    X_SPOOL,
    X_TABLE_POS,
    X_TABLE_VEL,
    X_VEL,
    adc,
    clamp_state,
    friction_force,
    plant_derivative,
    rk4_step,
)

__all__ = ["closed_loop", "LOOP_IDS", "ROWS"]

# loops
LOOP_POSITION = 0
LOOP_ACCELERATION = 1
LOOP_FORCE = 2
LOOP_OPEN = 3  # the reference is the valve command in volts (or the spool if direct)
LOOP_IDS = {"position": 0, "acceleration": 1, "force": 2, "open": 3}

# sensor vector layout
S_LVDT_RANGE = 0
S_LVDT_LSB = 1
S_ACCEL_RANGE = 2
S_ACCEL_LSB = 3
S_FORCE_RANGE = 4
S_FORCE_LSB = 5
S_DAC_LSB = 6
S_FULL_SCALE_V = 7  # command at full spool
S_NULL_BIAS = 8
N_SEN = 9

# output rows
R_DRIVE = 0
R_VALVE_CMD = 1
R_SPOOL = 2
R_P1 = 3
R_P2 = 4
R_POS = 5
R_VEL = 6
R_ACC = 7
R_FORCE = 8
R_PISTON = 9
R_LVDT = 10
R_ACCEL_M = 11
R_FORCE_M = 12
R_AUX = 13  # generated acceleration a_d (acceleration loop), else the reference
R_DRIVE_SAT = 14
R_SPOOL_SAT = 15
R_STROKE = 16
R_PRESSURE = 17
N_ROWS = 18
ROWS = (
    "drive_v",
    "valve_command_v",
    "spool",
    "p1_pa",
    "p2_pa",
    "displacement_m",
    "velocity_m_s",
    "acceleration_m_s2",
    "force_n",
    "piston_displacement_m",
    "lvdt_m",
    "accel_m_s2",
    "force_cell_n",
    "aux",
    "drive_saturated",
    "spool_saturated",
    "stroke_end",
    "pressure_limit",
)


@njit(cache=True)
def closed_loop(loop, ref, prm, sen, ctl, x0, cst0, drive0, noise, n_sub, h, delay, out):
    """Simulate ``ref.shape[0]`` control periods; fills ``out`` (N_ROWS, n).

    Parameters
    ----------
    loop : int
        LOOP_* id.
    ref : float64[n]
        Reference per control period (m, m/s², N, or V / spool for the open loop).
    prm : float64[N_PRM]
        Plant parameters (``ehss.plant._kernels`` layout).
    sen : float64[N_SEN]
        Sensor ranges, LSBs (0 = no quantisation), DAC LSB, command full scale, null bias.
    ctl : float64
        Controller coefficients (PID or TVC layout; unused in the open loop).
    x0 : float64[N_STATE]
        Initial plant state.
    cst0 : float64[5]
        Initial controller state.
    drive0 : float
        Drive held in the delay line before the first output.
    noise : float64[3, n]
        Sensor noise (LVDT, accelerometer, load cell) in SI units.
    n_sub, h, delay : int, float, int
        RK4 steps per period, their length, delay in periods.
    out : float64[N_ROWS, n]
    """
    n = ref.shape[0]
    x = x0.copy()
    cst = cst0.copy()
    work = np.empty((5, N_STATE))
    dx = np.empty(N_STATE)
    nbuf = delay + 1
    buf = np.full(nbuf, drive0)
    ap = prm[P_AP]
    stroke = prm[P_STROKE]
    ps = prm[P_PS]
    w_hp = prm[P_OMEGA_HP]
    spool_direct = prm[P_SPOOL_DIRECT] != 0.0
    saturate = prm[P_SATURATE] != 0.0
    # both coefficient layouts end with the output limit (PID_LIMIT, TVC_LIMIT)
    limit = ctl[ctl.shape[0] - 1]
    for k in range(n):
        # ------------------------------------------------------------ true signals at t_k
        plant_derivative(x, 0.0, prm, dx)
        a_table = dx[X_TABLE_VEL]
        pl = x[X_P1] - x[X_P2]
        # load cell: rod force Ap PL − Ff
        f_true = ap * pl - friction_force(x[X_VEL], prm)
        # accelerometer AC coupling: a_hp = a − ωa z
        a_hp = a_table - w_hp * x[X_HP]

        # ------------------------------------------------------------ sensors
        ym = adc(x[X_POS] + noise[0, k], sen[S_LVDT_RANGE], sen[S_LVDT_LSB])
        am = adc(a_hp + noise[1, k], sen[S_ACCEL_RANGE], sen[S_ACCEL_LSB])
        fm = adc(f_true + noise[2, k], sen[S_FORCE_RANGE], sen[S_FORCE_LSB])
        if k == 0:
            # no derivative kick on the first sample
            cst[2] = ym if loop != LOOP_FORCE else fm
            if loop == LOOP_ACCELERATION:
                cst[3] = ym
                cst[4] = am

        # ------------------------------------------------------------ controller
        aux = ref[k]
        if loop == LOOP_POSITION:
            u = pid_step(ref[k] - ym, ym, cst, ctl)
        elif loop == LOOP_FORCE:
            u = pid_step(ref[k] - fm, fm, cst, ctl)
        elif loop == LOOP_ACCELERATION:
            # generated acceleration a_d (before the generator state is advanced)
            aux = ctl[TVC_KG] * ref[k] - ctl[TVC_WG] * cst[1] - ctl[TVC_DG] * cst[0]
            u = tvc_step(ref[k], ym, am, cst, ctl)
        else:
            u = ref[k]
        sat = 0.0
        if loop != LOOP_OPEN:
            if u > limit:
                u = limit
                sat = 1.0
            elif u < -limit:
                u = -limit
                sat = 1.0
            # DAC over ±10 V
            u = adc(u, 10.0, sen[S_DAC_LSB])

        # ------------------------------------------------------------ delay line + ZOH
        buf[k % nbuf] = u
        applied = buf[(k + 1) % nbuf]
        if spool_direct:
            x[X_SPOOL] = applied
            ucmd = applied
        else:
            ucmd = applied / sen[S_FULL_SCALE_V] + sen[S_NULL_BIAS]

        # ------------------------------------------------------------ record t_k
        out[R_DRIVE, k] = u
        out[R_VALVE_CMD, k] = applied
        out[R_SPOOL, k] = x[X_SPOOL]
        out[R_P1, k] = x[X_P1]
        out[R_P2, k] = x[X_P2]
        out[R_POS, k] = x[X_TABLE_POS]
        out[R_VEL, k] = x[X_TABLE_VEL]
        out[R_ACC, k] = a_table
        out[R_FORCE, k] = f_true
        out[R_PISTON, k] = x[X_POS]
        out[R_LVDT, k] = ym
        out[R_ACCEL_M, k] = am
        out[R_FORCE_M, k] = fm
        out[R_AUX, k] = aux
        out[R_DRIVE_SAT, k] = sat
        out[R_SPOOL_SAT, k] = 1.0 if (saturate and abs(x[X_SPOOL]) >= 1.0) else 0.0
        out[R_STROKE, k] = 1.0 if abs(x[X_POS]) > stroke else 0.0
        p1 = x[X_P1]
        p2 = x[X_P2]
        out[R_PRESSURE, k] = 1.0 if (p1 <= 0.0 or p2 <= 0.0 or p1 >= ps or p2 >= ps) else 0.0

        # ------------------------------------------------------------ plant over one period
        for _ in range(n_sub):
            rk4_step(x, ucmd, prm, h, work)
            clamp_state(x, prm)
    return x
