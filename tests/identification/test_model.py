"""ArmaxModel: conversions, JSON, prediction, stability and rounding warnings."""

from __future__ import annotations

import json

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.signal import lfilter

from ehss.errors import DataError, EhssWarning, ParameterError
from ehss.identification.model import ArmaxModel

from .systems import DT_S, resonance_poles, system

F_HZ = np.linspace(0.5, 400.0, 300)


def _model(order=4, delay=1):
    a, b, c = system(order)
    return ArmaxModel(a=a, b=b, c=c, delay=delay, dt=DT_S, noise_variance=0.1,
                      meta={"n_samples": 10, "note": "x"})


def test_json_round_trip_bit_exact(tmp_path):
    m = _model()
    cov = np.diag(np.arange(1.0, 1.0 + m.na + m.nb + 1 + m.nc) / 3.0)
    m = ArmaxModel(**{**{k: getattr(m, k) for k in ("a", "b", "c", "delay", "dt",
                                                       "noise_variance", "meta")},
                      "covariance": cov})
    path = tmp_path / "m.json"
    m.save_json(path)
    back = ArmaxModel.load_json(path)
    for name in ("a", "b", "c", "covariance"):
        assert np.array_equal(getattr(back, name), getattr(m, name))
    assert back.delay == m.delay and back.dt == m.dt
    assert back.noise_variance == m.noise_variance and back.meta == m.meta
    d = json.loads(path.read_text())
    assert list(d)[:5] == ["a", "b", "c", "delay", "dt"]


def test_json_nan_noise_variance_and_bad_files(tmp_path):
    m = ArmaxModel(a=[1.0, -0.5], b=[1.0], dt=0.01)
    assert np.isnan(ArmaxModel.from_dict(json.loads(json.dumps(m.to_dict()))).noise_variance)
    with pytest.raises(DataError, match="does not exist"):
        ArmaxModel.load_json(tmp_path / "nope.json")
    (tmp_path / "bad.json").write_text("{")
    with pytest.raises(DataError, match="is not valid JSON"):
        ArmaxModel.load_json(tmp_path / "bad.json")
    with pytest.raises(DataError, match="lacks b, delay"):
        ArmaxModel.from_dict({"a": [1.0], "dt": 1.0})


@pytest.mark.parametrize("delay", [0, 1, 3])
def test_conversions_agree_with_frequency_response(delay):
    m = _model(4, delay)
    h = m.frequency_response(F_HZ)
    w = 2 * np.pi * F_HZ * DT_S
    import control

    # same rational function evaluated differently: 1e-9 relative (lightly damped)
    hc = np.asarray(control.frequency_response(m.to_control(), w / DT_S).complex).ravel()
    assert_allclose(hc, h, rtol=1e-9)
    _, hs = m.to_scipy().freqresp(w)
    assert_allclose(hs, h, rtol=1e-9)
    from scipy.signal import sosfreqz

    _, hsos = sosfreqz(m.to_sos(), worN=w)
    assert_allclose(hsos, h, rtol=1e-9)


def test_paper_form_round_trip_and_simulate():
    m = _model(6, 2)
    num, den = m.paper_form()
    assert num.size == den.size
    back = ArmaxModel.from_paper_form(num, den, dt=DT_S, c=m.c)
    assert np.array_equal(back.a, m.a) and np.array_equal(back.b, m.b)
    assert back.delay == 2
    u = np.random.default_rng(0).standard_normal(300)
    assert_allclose(m.simulate(u), lfilter(np.r_[0, 0, m.b], m.a, u), rtol=1e-13, atol=1e-13)
    assert_allclose(m.dc_gain(), 1.0, rtol=1e-12)
    assert m.is_stable() and m.check()
    assert m.poles().size == 6


def test_format_paper_full_precision():
    m = ArmaxModel(a=[1.0, -0.123456789012345678], b=[0.1], delay=1, dt=1e-3)
    s = m.format_paper()
    assert repr(-0.123456789012345678).lstrip("-") in s
    assert "0.1235" in m.format_paper(precision=4)


def test_predict_one_step_is_exact_on_armax_data(rng):
    # ARMAX data with zero initial conditions: the one-step predictor's error is ξ itself
    a, b, c = system(2)
    m = ArmaxModel(a=a, b=b, c=c, delay=1, dt=DT_S)
    u, xi = rng.standard_normal(500), rng.standard_normal(500)
    y = lfilter(np.r_[0, b], a, u) + lfilter(c, a, xi)
    assert_allclose(y - m.predict(u, y), xi, atol=1e-9)
    # horizon 2: error is F ξ with F = first two terms of C/A (MA(1) of ξ)
    f1 = c[1] - a[1]
    assert_allclose((y - m.predict(u, y, horizon=2))[2:], (xi + f1 * np.r_[0, xi[:-1]])[2:],
                    atol=1e-9)
    with pytest.raises(ParameterError, match="horizon=0 must be an integer >= 1"):
        m.predict(u, y, horizon=0)


def test_unstable_model_warns():
    m = ArmaxModel(a=[1.0, -1.05], b=[1.0], dt=1e-3)
    with pytest.warns(EhssWarning, match="unstable: max pole radius 1.05"):
        assert not m.check()
    assert not m.is_stable()


def test_rounding_to_four_digits_destabilises_lightly_damped_model():
    # 8th-order, lightly damped resonances (5–40 Hz, ζ = 0.02) at 1 kHz: the poles sit
    # within 1e-3 of the unit circle near z = 1 and the coefficients of A are ~10^2, so
    # 4 significant digits are far too few (PAPER.md §5 on eqs 23–25).
    poles = [p for f in (5.0, 10.0, 20.0, 40.0) for p in resonance_poles(f, 0.02)]
    a = np.real(np.poly(poles))
    m = ArmaxModel(a=a, b=[a.sum()], delay=1, dt=DT_S)
    assert m.is_stable()
    with pytest.warns(EhssWarning, match="rounding the model to 4 significant digits"):
        r = m.rounding_sensitivity(4)
    assert r.stability_changed and r.max_radius_rounded >= 1.0
    full = m.rounding_sensitivity(17, warn=False)
    assert not full.material and full.max_pole_shift == 0.0


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        (dict(a=[2.0, 1.0]), r"must start with 1"),
        (dict(c=[0.5]), r"must start with 1"),
        (dict(b=[]), r"must have at least one coefficient"),
        (dict(a=[1.0, np.nan]), r"must be finite"),
        (dict(delay=-1), r"delay=-1 must be an integer >= 0"),
        (dict(dt=0.0), r"dt=0.0 must be a finite number > 0"),
        (dict(covariance=np.eye(2)), r"covariance shape \(2, 2\) must be \(3, 3\)"),
    ],
)
def test_bad_model_fields(kwargs, message):
    base = dict(a=[1.0, -0.5], b=[1.0], c=[1.0, 0.2], delay=1, dt=1e-3)
    with pytest.raises(ParameterError, match=message):
        ArmaxModel(**{**base, **kwargs})
