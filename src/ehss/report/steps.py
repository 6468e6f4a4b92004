"""Step-response figures of merit (rise time, overshoot, settling time)."""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

__all__ = ["StepMetrics", "step_metrics"]


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
