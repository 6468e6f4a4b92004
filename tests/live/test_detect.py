"""Change figures against analytic answers, and the hold-time logic."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ehss.errors import ParameterError
from ehss.live.detect import DetectionSettings, Detector, dominant_pole, figures


def test_dominant_pole_of_a_damped_pair():
    # z = r e^{±jθ} with r = e^{-σ dt}, θ = ω dt  →  s = −σ + jω exactly
    dt, sigma, omega = 1e-3, 30.0, 2 * np.pi * 25.0
    r, th = math.exp(-sigma * dt), omega * dt
    a = np.poly([r * np.exp(1j * th), r * np.exp(-1j * th), 0.3])
    s = dominant_pole(a.real, dt)
    assert s.real == pytest.approx(-sigma, rel=1e-9)   # roots of a cubic: ~1e-13
    assert s.imag == pytest.approx(omega, rel=1e-9)


def test_figures_of_a_pure_gain_change():
    # H = 2 H_ref: every point 6.0206 dB apart, same poles
    h_ref = np.exp(1j * np.linspace(0, 3, 20)) / np.linspace(1, 4, 20)
    f = figures(2 * h_ref, h_ref, -5 + 3j, -5 + 3j)
    np.testing.assert_allclose(f, [20 * math.log10(2), 20 * math.log10(2), 0.0], atol=1e-12)


def test_model_response_matches_armax_model(tmp_path):
    # the channel's cheap response from θ̂ equals ArmaxModel.frequency_response
    from ehss.live.channel import ChannelProcessor, EstimatorSettings

    est = EstimatorSettings(na=2, nb=1, nc=0, delay=1, u_scale=1.0, y_scale=1.0)
    proc = ChannelProcessor("1", 100.0, est, DetectionSettings(learn_s=1.0, band_hz=(1, 20)))
    rng = np.random.default_rng(3)
    u = rng.standard_normal(300)
    from scipy.signal import lfilter
    y = lfilter([0, 0.5, 0.2], [1, -1.2, 0.5], u)
    proc.feed(u, y)
    proc.evaluate(3.0, proc.capture())
    grid, h, _ = proc.model_response()
    np.testing.assert_allclose(h, proc.estimator.model.frequency_response(grid), rtol=1e-12)


def test_detector_waits_for_the_hold_time_and_clears():
    det = Detector(DetectionSettings(frf_db=1.0, gain_db=3.0, pole_shift=0.5, hold_s=0.2,
                                     clear_s=0.3))
    over, under = np.array([2.0, 0, 0]), np.array([0.1, 0, 0])
    assert det.step(0.0, over) is None
    assert det.step(0.1, under) is None         # interrupted: starts again
    assert [det.step(t, over) for t in (0.2, 0.3)] == [None, None]
    assert det.step(0.4, over) == "alarm"      # 0.2 s beyond the threshold
    assert det.exceeded(over) == ["frf_db"]
    assert [det.step(t, under) for t in (0.5, 0.6, 0.7)] == [None, None, None]
    assert det.step(0.8, under) == "clear"


def test_nan_raises_nothing():
    det = Detector(DetectionSettings(hold_s=0.2))
    assert det.exceeded(np.array([np.nan, 0, np.nan])) == []


def test_dominant_pole_in_band_only():
    # a slow real pole at 0.2 Hz (closest to the circle) and a pair at 25 Hz
    dt = 1e-3
    zs = [np.exp(-2 * np.pi * 0.2 * dt),
          np.exp((-30 + 2j * np.pi * 25) * dt), np.exp((-30 - 2j * np.pi * 25) * dt)]
    a = np.poly(zs).real
    assert abs(dominant_pole(a, dt)) == pytest.approx(2 * np.pi * 0.2, rel=1e-6)
    s = dominant_pole(a, dt, (1.0, 50.0))
    assert s.imag == pytest.approx(2 * np.pi * 25, rel=1e-9)
    assert math.isnan(dominant_pole(a, dt, (60.0, 100.0)).real)


@pytest.mark.parametrize("kw", [{"compare": "x"}, {"frf_db": 0}, {"hold_s": -1},
                                {"band_hz": (5, 1)}])
def test_bad_settings(kw):
    with pytest.raises(ParameterError):
        DetectionSettings(**kw)

