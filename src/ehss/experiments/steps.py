"""Step tests of the three loops (Fig. 12) and their figures of merit.

The figures of merit (rise time, overshoot, settling time, steady-state error) are read
from any step response; :func:`step_tests` runs the paper's three steps on the rig.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy.signal import lfilter

from ehss import signals
from ehss.control.known import known_factors
from ehss.params import GRAVITY_M_S2, RigParams
from ehss.simulation import SimulationResult, simulate

__all__ = ["StepMetrics", "step_metrics", "StepTest", "STEP_SIZES", "step_tests"]

#: Fig. 12's steps in SI units: 5 mm, 0.05 g and 1 kN.
STEP_SIZES = {"position": 5.0e-3, "acceleration": 0.05 * GRAVITY_M_S2, "force": 1000.0}


@dataclass(frozen=True, kw_only=True)
class StepMetrics:
    """Figures of merit of one step response.

    Attributes
    ----------
    amplitude : float
        Size of the commanded step (SI units of the loop).
    rise_time_s : float
        Time from 10 % to 90 % of the step (nan when 90 % is never reached).
    overshoot_pct : float
        Peak beyond the final value, in percent of the step.
    settling_time_s : float
        Time after the step after which the error to ``target`` stays within
        ``tolerance`` of the step (nan when it never settles).
    steady_state_error_pct : float
        Mean error to ``target`` over the last 10 % of the record, percent of the step.
    drive_saturated_pct : float
        Share of samples where the drive was at its limit.
    """

    amplitude: float
    rise_time_s: float
    overshoot_pct: float
    settling_time_s: float
    steady_state_error_pct: float
    drive_saturated_pct: float

    def to_dict(self) -> dict[str, float]:
        return {k: float(v) for k, v in asdict(self).items()}


def step_metrics(
    t: np.ndarray,
    output: np.ndarray,
    *,
    step_time_s: float,
    amplitude: float,
    baseline: float = 0.0,
    target: np.ndarray | None = None,
    drive: np.ndarray | None = None,
    drive_limit: float = 10.0,
    tolerance: float = 0.05,
) -> StepMetrics:
    """Rise time, overshoot, settling time and steady-state error of a step response.

    Parameters
    ----------
    t, output : ndarray, shape (n,)
        Time (s) and measured response.
    step_time_s : float
        When the step was applied.
    amplitude : float
        Step size; ``baseline`` is the level before the step.
    target : ndarray, shape (n,), optional
        The response the loop should follow (the ideal step by default). For the
        acceleration loop it is the generator's high-passed step, eqs (10) and (13).
    drive : ndarray, shape (n,), optional
        Controller output, to report the share of saturated samples.
    tolerance : float
        Settling band as a fraction of the step.
    """
    t = np.asarray(t, dtype=float)
    y = (np.asarray(output, dtype=float) - baseline) / amplitude
    after = t >= step_time_s
    if target is None:
        ref = np.where(after, 1.0, 0.0)
    else:
        ref = (np.asarray(target, dtype=float) - baseline) / amplitude
    ta, ya, ra = t[after], y[after], ref[after]
    # Rise: from 10 % to 90 % of the way to the target (the target may move, as the
    # acceleration loop's high-passed step does, eq (13)).
    i10 = np.flatnonzero(ya >= 0.1 * ra)
    i90 = np.flatnonzero(ya >= 0.9 * ra)
    rise = float(ta[i90[0]] - ta[i10[0]]) if i10.size and i90.size else float("nan")
    overshoot = max(0.0, float(np.max(ya - ra)))
    # Settling on a 5 ms moving average, so that sensor noise alone does not count.
    width = max(1, int(round(0.005 / np.median(np.diff(t))))) if t.size > 1 else 1
    smooth = np.convolve(y - ref, np.ones(width) / width, mode="same")
    outside = np.flatnonzero(after & (np.abs(smooth) > tolerance))
    n_tail = max(1, ya.size // 10)
    if outside.size == 0:
        settling = 0.0
    elif outside[-1] >= t.size - max(1, ya.size // 20) - width:
        settling = float("nan")
    else:
        settling = float(t[outside[-1] + 1] - step_time_s)
    sse = float(np.mean(y[-n_tail:] - ref[-n_tail:]))
    sat = 0.0
    if drive is not None:
        sat = float(np.mean(np.abs(np.asarray(drive)) >= 0.999 * drive_limit)) * 100.0
    return StepMetrics(
        amplitude=float(amplitude),
        rise_time_s=rise,
        overshoot_pct=100.0 * overshoot,
        settling_time_s=settling,
        steady_state_error_pct=100.0 * sse,
        drive_saturated_pct=sat,
    )


@dataclass(frozen=True, kw_only=True)
class StepTest:
    """One step test: the run, its figures of merit and the response it should follow."""

    loop: str
    result: SimulationResult
    metrics: StepMetrics
    target: np.ndarray


def step_tests(
    params: RigParams, *, duration_s: float = 1.0, seed: int = 0, start_s: float = 0.1
) -> dict[str, StepTest]:
    """Fig. 12: a step of :data:`STEP_SIZES` on each loop of the rig.

    The acceleration step asks the generator for Kg·a/δg = 50 mm of displacement, half
    the stroke; its target is the high-passed step of eq (13).

    Parameters
    ----------
    params : RigParams
        The rig.
    duration_s : float
        Length of each record.
    seed : int
        The loops' sensor noise uses ``seed + 100``, ``+ 101`` and ``+ 102``.
    start_s : float
        When the step is applied.
    """
    fs = params.timing.control_rate_hz
    out: dict[str, StepTest] = {}
    for k, (loop, amp) in enumerate(STEP_SIZES.items()):
        ref = signals.step(amp, duration_s=duration_s, fs=fs, start_s=start_s)
        res = simulate(loop, ref, params=params, seed=seed + 100 + k)
        target = None
        if loop == "acceleration":
            target = generator_step_target(params, res.t, start_s, amp)
        limit = getattr(params, loop).output_limit_v
        m = step_metrics(
            res.t,
            res.output,
            step_time_s=start_s,
            amplitude=amp,
            target=target,
            drive=res.signals["drive_v"],
            drive_limit=limit,
        )
        ideal = np.where(res.t >= start_s, amp, 0.0) if target is None else target
        out[loop] = StepTest(loop=loop, result=res, metrics=m, target=ideal)
    return out


def generator_step_target(
    params: RigParams, t: np.ndarray, start_s: float, amplitude: float
) -> np.ndarray:
    """What the accelerometer should read for a step: the generator's high-passed step of
    eqs (10), (13), seen through the accelerometer's AC coupling (both known factors)."""
    num, den = known_factors("acceleration", params)
    return lfilter(num, den, np.where(t >= start_s, amplitude, 0.0))
