"""The closed-loop simulation in one numba kernel (plant + sensors + controller + delay).

Timing of one control period k (t_k = k dt, dt = 1/fs):

1. sample the sensors on the plant state x(t_k) (noise, ADC quantisation);
2. run the controller → drive[k], clip to ±limit, DAC-quantise;
3. push drive[k] into the delay line; the valve receives drive[k − delay] (held, ZOH);
4. integrate the plant over [t_k, t_{k+1}) with ``substeps`` RK4 steps.

Everything recorded at index k refers to t_k. No allocation inside the loop.

The controller's memory, the delay line and the count of periods already simulated
live in one float64 array (``mem``, laid out by :data:`MEM_K`, :data:`MEM_PID`,
:data:`MEM_TVC`, :data:`MEM_BUF`) that the kernel reads at its start and writes back at
its end, so that a run continues where the previous one stopped: simulating [0, T) in
blocks gives the same samples as one run.

The kernel reads a :class:`LoopSettings` (the plant's, the sensors' and the controllers'
settings, the timing), a :class:`SensorNoise` and writes a :class:`LoopRecord` of named
rows; the plant and the controllers come from their packages' public kernels
(:mod:`ehss.plant.kernels`, :mod:`ehss.control.kernels`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from ehss.control.kernels import PidSettings, PidState, TvcSettings, TvcState, pid_step, tvc_step
from ehss.plant.kernels import (
    PlantSettings,
    PlantState,
    adc,
    clamp_state,
    friction_force,
    plant_derivative,
    rk4_step,
    with_spool,
)

__all__ = [
    "LOOP_IDS",
    "MEM_BUF",
    "MEM_K",
    "MEM_PID",
    "MEM_TVC",
    "LoopRecord",
    "LoopSettings",
    "SensorNoise",
    "SensorSettings",
    "closed_loop",
]

# loops (the values of LoopSettings.loop)
POSITION = 0
ACCELERATION = 1
FORCE = 2
OPEN = 3  # the reference is the valve command in volts (or the spool if prescribed)
LOOP_IDS = {"position": POSITION, "acceleration": ACCELERATION, "force": FORCE, "open": OPEN}

# layout of the loop's memory ``mem``: periods simulated, PidState, TvcState, delay line
MEM_K = 0
MEM_PID = 1  # 3 values (PidState)
MEM_TVC = 4  # 5 values (TvcState)
MEM_BUF = 9  # delay_samples + 1 values, drive[k] at index k mod (delay_samples + 1)


class SensorSettings(NamedTuple):
    """Sensor ranges and quantisation, and the valve command's scaling."""

    lvdt_range_m: float  # LVDT clipped to ±range
    lvdt_lsb_m: float  # LVDT quantisation step (0: none)
    accel_range_m_s2: float
    accel_lsb_m_s2: float
    force_range_n: float
    force_lsb_n: float
    dac_lsb_v: float  # drive quantisation step over ±10 V (0: none)
    command_full_scale_v: float  # command at full spool
    null_bias: float  # spool offset at zero command, fraction of full spool


class LoopSettings(NamedTuple):
    """Everything the loop kernel needs besides the signals.

    A PID starts with ``drive0_v`` in its integral, so that its first output holds the
    drive already in the delay line (bumpless start, e.g. on a static force).
    """

    loop: int  # POSITION, ACCELERATION, FORCE or OPEN
    plant: PlantSettings
    sensors: SensorSettings
    pid: PidSettings  # controller of the position and force loops (else unused)
    tvc: TvcSettings  # controller of the acceleration loop (else unused)
    substeps: int  # RK4 steps per control period
    step_s: float  # h, length of one RK4 step
    delay_samples: int  # control periods between the controller and the valve
    drive0_v: float  # drive in the delay line before the first output, and a PID's integral


class SensorNoise(NamedTuple):
    """Additive sensor noise per control period, SI units, each shape (n,)."""

    lvdt_m: np.ndarray
    accel_m_s2: np.ndarray
    force_n: np.ndarray


class LoopRecord(NamedTuple):
    """Rows written by :func:`closed_loop`, each shape (n,), sampled at t_k."""

    drive_v: np.ndarray  # controller output after clipping and the DAC
    valve_command_v: np.ndarray  # drive reaching the valve after the delay
    spool: np.ndarray
    p1_pa: np.ndarray
    p2_pa: np.ndarray
    displacement_m: np.ndarray  # table
    velocity_m_s: np.ndarray  # table
    acceleration_m_s2: np.ndarray  # table
    force_n: np.ndarray  # rod force Ap PL − Ff
    piston_displacement_m: np.ndarray
    lvdt_m: np.ndarray  # measured
    accel_m_s2: np.ndarray  # measured
    force_cell_n: np.ndarray  # measured
    aux: np.ndarray  # generated acceleration a_d (acceleration loop), else the reference
    drive_saturated: np.ndarray  # 0/1
    spool_saturated: np.ndarray  # 0/1
    stroke_end: np.ndarray  # 0/1
    pressure_limit: np.ndarray  # 0/1


@njit(cache=True)
def closed_loop(ref: np.ndarray, noise: SensorNoise, x0: PlantState, s: LoopSettings,
                rec: LoopRecord, mem: np.ndarray) -> PlantState:
    """Simulate ``ref.shape[0]`` control periods; fills ``rec``, returns the final state.

    Parameters
    ----------
    ref : float64[n]
        Reference per control period (m, m/s², N, or V / spool for the open loop).
    noise : SensorNoise
        Sensor noise per period (LVDT, accelerometer, load cell) in SI units.
    x0 : PlantState
        Initial plant state.
    s : LoopSettings
    rec : LoopRecord
        Preallocated rows of length n.
    mem : float64[MEM_BUF + delay_samples + 1]
        Controller memory and delay line at the start (see the module notes); holds
        them at the end on return.
    """
    p = s.plant
    sen = s.sensors
    ap = p.piston_area_m2
    ps = p.supply_pressure_pa
    limit = s.tvc.output_limit_v if s.loop == ACCELERATION else s.pid.output_limit_v
    x = x0
    nbuf = s.delay_samples + 1
    k0 = int(mem[MEM_K])
    buf = mem[MEM_BUF:MEM_BUF + nbuf]  # a view: the delay line is written in place
    pid = PidState(mem[MEM_PID], mem[MEM_PID + 1], mem[MEM_PID + 2])
    tvc = TvcState(mem[MEM_TVC], mem[MEM_TVC + 1], mem[MEM_TVC + 2], mem[MEM_TVC + 3],
                   mem[MEM_TVC + 4])
    for k in range(ref.shape[0]):
        g = k0 + k  # period index since the start of the test
        # ------------------------------------------------------------ true signals at t_k
        a_table = plant_derivative(x, 0.0, p).velocity_m_s
        # load cell: rod force Ap PL − Ff
        f_true = ap * (x.p1_pa - x.p2_pa) - friction_force(x.piston_velocity_m_s, p)
        # accelerometer AC coupling: a_hp = a − ωa z
        a_hp = a_table - p.accel_highpass_rad_s * x.accel_highpass_state_m_s

        # ------------------------------------------------------------ sensors
        ym = adc(x.piston_displacement_m + noise.lvdt_m[k], sen.lvdt_range_m, sen.lvdt_lsb_m)
        am = adc(a_hp + noise.accel_m_s2[k], sen.accel_range_m_s2, sen.accel_lsb_m_s2)
        fm = adc(f_true + noise.force_n[k], sen.force_range_n, sen.force_lsb_n)
        if g == 0:
            # no derivative kick on the first sample: the previous measurements are these;
            # the generator and the velocity estimate v̂ start from rest
            pid = PidState(pid.integral_v, 0.0, fm if s.loop == FORCE else ym)
            tvc = TvcState(rd_m=0.0, vd_m_s=0.0, v_hat_m_s=0.0, y_prev_m=ym, a_prev_m_s2=am)

        # ------------------------------------------------------------ controller
        r = ref[k]
        aux = r
        if s.loop == POSITION:
            u, pid = pid_step(r - ym, ym, pid, s.pid)
        elif s.loop == FORCE:
            u, pid = pid_step(r - fm, fm, pid, s.pid)
        elif s.loop == ACCELERATION:
            # aux: the generated acceleration a_d, eq (10)
            u, aux, tvc = tvc_step(r, ym, am, tvc, s.tvc)
        else:
            u = r
        sat = 0.0
        if s.loop != OPEN:
            if u > limit:
                u = limit
                sat = 1.0
            elif u < -limit:
                u = -limit
                sat = 1.0
            # DAC over ±10 V
            u = adc(u, 10.0, sen.dac_lsb_v)

        # ------------------------------------------------------------ delay line + ZOH
        buf[g % nbuf] = u
        applied = buf[(g + 1) % nbuf]
        if p.spool_prescribed:
            # the drive is the spool position itself, held over the period
            x = with_spool(x, applied)
            ucmd = applied
        else:
            ucmd = applied / sen.command_full_scale_v + sen.null_bias

        # ------------------------------------------------------------ record t_k
        rec.drive_v[k] = u
        rec.valve_command_v[k] = applied
        rec.spool[k] = x.spool
        rec.p1_pa[k] = x.p1_pa
        rec.p2_pa[k] = x.p2_pa
        rec.displacement_m[k] = x.displacement_m
        rec.velocity_m_s[k] = x.velocity_m_s
        rec.acceleration_m_s2[k] = a_table
        rec.force_n[k] = f_true
        rec.piston_displacement_m[k] = x.piston_displacement_m
        rec.lvdt_m[k] = ym
        rec.accel_m_s2[k] = am
        rec.force_cell_n[k] = fm
        rec.aux[k] = aux
        rec.drive_saturated[k] = sat
        rec.spool_saturated[k] = 1.0 if (p.spool_saturates and abs(x.spool) >= 1.0) else 0.0
        rec.stroke_end[k] = 1.0 if abs(x.piston_displacement_m) > p.half_stroke_m else 0.0
        p1 = x.p1_pa
        p2 = x.p2_pa
        rec.pressure_limit[k] = 1.0 if (p1 <= 0.0 or p2 <= 0.0 or p1 >= ps or p2 >= ps) else 0.0

        # ------------------------------------------------------------ plant over one period
        for _ in range(s.substeps):
            x = clamp_state(rk4_step(x, ucmd, p, s.step_s), p)
    mem[MEM_K] = k0 + ref.shape[0]
    mem[MEM_PID], mem[MEM_PID + 1], mem[MEM_PID + 2] = pid
    mem[MEM_TVC], mem[MEM_TVC + 1], mem[MEM_TVC + 2], mem[MEM_TVC + 3], mem[MEM_TVC + 4] = tvc
    return x
