from __future__ import annotations

import math

import numpy as np
import pytest

from ehss.experiments.steps import step_metrics


def test_first_order_step_has_analytic_figures():
    tau, fs, t0 = 0.02, 100_000.0, 0.1
    t = np.arange(0.0, 1.0, 1.0 / fs)
    y = np.where(t >= t0, 1.0 - np.exp(-(t - t0) / tau), 0.0) * 3.0
    m = step_metrics(t, y, step_time_s=t0, amplitude=3.0)
    # 10-90 % rise of a first-order lag is τ ln 9 (to 1/fs). Settling is read on a 5 ms
    # centred moving average of the error e^{-t/τ}, which is e^{-t/τ} sinh(x)/x with
    # x = 2.5 ms/τ: 5 % is reached at τ ln(20 sinh(x)/x).
    assert m.rise_time_s == pytest.approx(tau * math.log(9.0), abs=2.0 / fs)
    x = 0.0025 / tau
    expected = tau * math.log(20.0 * math.sinh(x) / x)
    assert m.settling_time_s == pytest.approx(expected, abs=2.0 / fs)
    assert m.overshoot_pct == 0.0
    assert abs(m.steady_state_error_pct) < 1e-9


def test_second_order_overshoot():
    zeta, wn, fs = 0.5, 50.0, 50_000.0
    t = np.arange(0.0, 1.0, 1.0 / fs)
    wd = wn * math.sqrt(1 - zeta**2)
    phi = math.acos(zeta)
    y = 1 - np.exp(-zeta * wn * t) * np.sin(wd * t + phi) / math.sqrt(1 - zeta**2)
    m = step_metrics(t, y, step_time_s=0.0, amplitude=1.0, drive=np.full(t.size, 10.0))
    # Peak overshoot exp(-πζ/√(1-ζ²)) = 16.3 %.
    expected = 100 * math.exp(-math.pi * zeta / math.sqrt(1 - zeta**2))
    assert m.overshoot_pct == pytest.approx(expected, abs=0.01)
    assert m.drive_saturated_pct == 100.0


def test_never_settling_is_nan():
    t = np.linspace(0, 1, 1000)
    y = np.where(t > 0.1, 0.5, 0.0)
    m = step_metrics(t, y, step_time_s=0.1, amplitude=1.0)
    assert math.isnan(m.rise_time_s) and math.isnan(m.settling_time_s)
    assert m.steady_state_error_pct == pytest.approx(-50.0)
