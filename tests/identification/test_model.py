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
    with pytest.raises(DataError, match="lacks the fields b, delay"):
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


def test_simulate_with_innovation_follows_the_difference_equation():
    # A y = q^-d B u + C e, written out sample by sample from the definition
    m = ArmaxModel(a=[1.0, -0.8, 0.15], b=[0.5, 0.2], c=[1.0, 0.5], delay=2, dt=DT_S)
    rng = np.random.default_rng(3)
    u, e = rng.standard_normal(200), 0.1 * rng.standard_normal(200)
    y = np.zeros(200)
    for k in range(200):
        y[k] = (sum(m.b[i] * u[k - 2 - i] for i in range(2) if k - 2 - i >= 0)
                + e[k] + sum(m.c[i] * e[k - i] for i in range(1, 2) if k - i >= 0)
                - sum(m.a[i] * y[k - i] for i in range(1, 3) if k - i >= 0))
    # summation order differs from lfilter's: a few ulps of |y| ~ 1
    assert_allclose(m.simulate(u, innovation=e), y, rtol=0, atol=1e-13)
    assert_allclose(m.simulate(u), m.simulate(u, innovation=np.zeros(200)), rtol=0, atol=0)
    with pytest.raises(DataError, match="innovation has shape"):
        m.simulate(u, innovation=e[:-1])


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
    with pytest.raises(ParameterError, match=r"horizon=0 must be an integer in \[1, inf\)"):
        m.predict(u, y, horizon=0)
    with pytest.raises(TypeError, match=r"horizon=1.0 must be an integer, not float"):
        m.predict(u, y, horizon=1.0)


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
        (dict(delay=-1), r"delay=-1 must be an integer in \[0, inf\)"),
        (dict(dt=0.0), r"dt=0.0 must be in \(0, inf\) s"),
        (dict(dt=float("inf")), r"dt=inf must be finite"),
        (dict(covariance=np.eye(2)), r"covariance shape \(2, 2\) must be \(3, 3\)"),
    ],
)
def test_bad_model_fields(kwargs, message):
    base = dict(a=[1.0, -0.5], b=[1.0], c=[1.0, 0.2], delay=1, dt=1e-3)
    with pytest.raises(ParameterError, match=message):
        ArmaxModel(**{**base, **kwargs})


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        (dict(a=["1", "-0.5"]), r"a=\['1', '-0.5'\] must be a sequence of real numbers"),
        (dict(b=[1.0, None]), r"b=\[1.0, None\] must be a sequence of real numbers"),
        (dict(c=[[1.0], [0.2, 0.1]]), r"c=.* must be a sequence of real numbers"),
        (dict(delay=1.0), r"delay=1.0 must be an integer, not float"),
        (dict(dt="1e-3"), r"dt='1e-3' must be a real number, not str"),
        (dict(noise_variance="0.1"), r"noise_variance='0.1' must be a real number"),
        (dict(offsets=1.0), r"offsets=1.0 must be a pair of numbers, not float"),
        (dict(offsets=(0.0, "1")), r"offsets\[1\]='1' must be a real number"),
    ],
)
def test_wrong_field_types_raise_type_error(kwargs, message):
    base = dict(a=[1.0, -0.5], b=[1.0], c=[1.0, 0.2], delay=1, dt=1e-3)
    with pytest.raises(TypeError, match=message):
        ArmaxModel(**{**base, **kwargs})


def test_rounding_digits_are_checked():
    m = ArmaxModel(a=[1.0, -0.5], b=[1.0], dt=1e-3)
    with pytest.raises(ParameterError, match=r"digits=0 must be an integer in \[1, inf\)"):
        m.rounding_sensitivity(0)
    with pytest.raises(TypeError, match=r"digits=4.0 must be an integer, not float"):
        m.rounding_sensitivity(4.0)


# ----------------------------------------------------------------- model files on load
_GOOD = {"a": [1.0, -0.5], "b": [0.5, 0.1], "c": [1.0, 0.2], "delay": 1, "dt": 0.001}


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"a": "1, -0.5"}, r"field 'a' = '1, -0.5' must be a list of numbers, not a string"),
        ({"a": [[1.0, -0.5]]}, r"field 'a' must be a flat list .* entry 0 is a list"),
        ({"b": [0.5, [0.1, 0.2]]}, r"field 'b' must be a flat list .* entry 1"),
        ({"b": ["0.5"]}, r"field 'b\[0\]' = '0.5' must be a number, not a string"),
        ({"b": [True]}, r"field 'b\[0\]' = True must be a number"),
        ({"b": [0.0, 0.0]}, r"field 'b' is all zeros"),
        ({"b": []}, r"field 'b' is empty"),
        ({"a": [2.0, 1.0]}, r"field 'a' must start with 1"),
        ({"c": [1.0, float("nan")]}, r"field 'c\[1\]' = nan must be finite"),
        ({"a": [1.0, 10**400]}, r"field 'a\[1\]' = .* is too large"),
        ({"a": [1.0] + [0.0] * 2000}, r"field 'a' has 2001 entries; at most 1001"),
        ({"delay": 1.5}, r"field 'delay' = 1.5 must be a whole number"),
        ({"delay": "1"}, r"field 'delay' = '1' must be a whole number"),
        ({"delay": 10**12}, r"field 'delay' = 1000000000000 must be in \[0, 100000\]"),
        ({"delay": -1}, r"field 'delay' = -1 must be in \[0, 100000\]"),
        ({"dt": "0.001"}, r"field 'dt' = '0.001' must be a number"),
        ({"dt": 0.0}, r"field 'dt' = 0.0 s must be a sample period in \[1e-09, 1e\+09\] s"),
        ({"dt": 1e-310}, r"field 'dt'"),
        ({"noise_variance": -1.0}, r"field 'noise_variance' = -1.0 must be >= 0"),
        ({"covariance": [[1.0]]}, r"field 'covariance' must be a list of 4 rows of 4"),
        ({"covariance": [[1.0] * 4] * 3 + [[1.0] * 3]}, r"field 'covariance' must be a list of 4"),
        ({"meta": [1]}, r"field 'meta' must be an object, not a list"),
        ({"offsets": [0.0, 1.0]}, r"field 'offsets' must be an object"),
        ({"offsets": {"input": "0", "output": 1.0}}, r"field 'offsets.input' = '0'"),
        ({"band_hz": [10.0, 1.0]}, r"field 'band_hz' = \[10.0, 1.0\] must satisfy"),
        ({"band_hz": [1.0, 600.0]}, r"field 'band_hz' = \[1.0, 600.0\] must .* fs/2 = 500 Hz"),
        ({"band_hz": "1-10"}, r"field 'band_hz' = '1-10' must be a list"),
        ({"meta": {"known_factors": [1.0]}}, r"field 'meta.known_factors' must be an object"),
        ({"meta": {"known_factors": {"num": ["x"], "den": [1.0]}}},
         r"field 'meta.known_factors.num\[0\]' = 'x' must be a number"),
        ({"meta": {"known_factors": {"num": [1.0], "den": [1.0, -2.0]}}},
         r"field 'meta.known_factors': den has a pole on or outside the unit circle"),
        ({"meta": {"known_factors": {"num": [1.0, -0.3], "den": [1.0]}}},
         r"field 'meta.known_factors': num does not divide the model's 'b'"),
        ({"meta": {"known_factors": {"num": [1.0, 1.0, 1.0], "den": [1.0]}}},
         r"field 'meta.known_factors': num is longer than the model's 'b'"),
    ],
)
def test_malformed_model_fields_name_file_and_field(tmp_path, change, message):
    path = tmp_path / "m.json"
    path.write_text(json.dumps({**_GOOD, **change}))
    with pytest.raises(DataError, match=r"model file '.*m.json': " + message):
        ArmaxModel.load_json(path)


def test_known_factors_that_divide_the_model_are_accepted(tmp_path):
    from ehss.identification.known import compose

    rest = ArmaxModel(a=[1.0, -0.5], b=[0.5, 0.1], dt=0.001)
    full = compose(rest, np.array([1.0, -0.9]), np.array([1.0, -0.2]))
    path = tmp_path / "m.json"
    full.save_json(path)
    back = ArmaxModel.load_json(path)
    assert back.meta["known_factors"] == {"num": [1.0, -0.9], "den": [1.0, -0.2]}
    assert_allclose(back.b, full.b, rtol=0, atol=0)


def test_integral_float_delay_and_extra_keys_are_accepted(tmp_path):
    path = tmp_path / "m.json"
    path.write_text(json.dumps({**_GOOD, "delay": 2.0, "validation": {"fit": 90}}))
    assert ArmaxModel.load_json(path).delay == 2


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"", "is empty"),
        (b"  \n", "is empty"),
        (b'{"a": [1.0], "b": [1.0], "delay": 1, "dt": 1.0, "x": "\xff"}', "not UTF-8"),
        (b"[" * 100_000 + b"]" * 100_000, "nested too deeply"),
        (b"[1, 2]", "does not hold a JSON object"),
        (b"{", "is not valid JSON"),
    ],
)
def test_unreadable_model_files(tmp_path, content, message):
    path = tmp_path / "m.json"
    path.write_bytes(content)
    with pytest.raises(DataError, match=message):
        ArmaxModel.load_json(path)


def test_model_file_folder_and_path_under_a_file(tmp_path):
    with pytest.raises(DataError, match="is a folder"):
        ArmaxModel.load_json(tmp_path)
    (tmp_path / "f").write_text("x")
    # a path through a regular file cannot be opened, as an unreadable file cannot (the
    # tests may run as root, for whom permission bits do not stop reading)
    with pytest.raises(DataError, match="cannot read model file"):
        ArmaxModel.load_json(tmp_path / "f" / "m.json")


@pytest.mark.parametrize(("kwargs", "message"), [
    (dict(delay=1.0), r"delay=1.0 must be an integer, not float"),
    (dict(delay="1"), r"delay='1' must be an integer, not str"),
    (dict(delay=True), r"delay=True must be an integer"),
    (dict(dt="0.001"), r"dt='0.001' must be a real number, not str"),
])
def test_wrong_python_types_are_type_errors(kwargs, message):
    with pytest.raises(TypeError, match=message):
        ArmaxModel(**{"a": [1.0, -0.5], "b": [1.0], **kwargs})


def test_utf8_byte_order_mark_is_accepted(tmp_path):
    path = tmp_path / "m.json"
    path.write_bytes(b"\xef\xbb\xbf" + json.dumps(_GOOD).encode())
    assert ArmaxModel.load_json(path).delay == 1


def test_from_theta_is_the_inverse_of_theta(rng):
    theta = rng.standard_normal(2 + 3 + 1)
    cov = np.eye(6)
    m = ArmaxModel.from_theta(theta, na=2, nb=2, nc=1, delay=3, dt=1e-3,
                              noise_variance=0.5, covariance=cov, meta={"method": "x"})
    assert np.array_equal(m.theta, theta)
    assert (m.na, m.nb, m.nc, m.delay) == (2, 2, 1, 3)
    assert np.array_equal(m.a, np.r_[1.0, theta[:2]]) and np.array_equal(m.b, theta[2:5])
    assert m.noise_variance == 0.5 and np.array_equal(m.covariance, cov)
    assert m.meta == {"method": "x"}


def test_from_theta_keeps_an_estimator_result_valid():
    bad = np.full((2, 2), np.inf)
    m = ArmaxModel.from_theta([0.5, 1.0], na=1, nb=0, nc=0, delay=1, dt=1.0,
                              noise_variance=np.inf, covariance=bad)
    # an overflowed variance is unknown, an overflowed covariance absent
    assert np.isnan(m.noise_variance) and m.covariance is None
    with pytest.raises(ParameterError, match="theta has 2 coefficients"):
        ArmaxModel.from_theta([0.5, 1.0], na=1, nb=1, nc=0, delay=1, dt=1.0)
