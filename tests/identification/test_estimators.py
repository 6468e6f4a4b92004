"""``estimate``: one method vocabulary, and recursive estimators started from a batch fit."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from numpy.testing import assert_allclose

from ehss.errors import EhssWarning, ParameterError
from ehss.identification import METHODS, estimate
from ehss.identification.model import ArmaxModel

from .systems import DT_S, armax_data, system


def _frf_error(model, truth):
    f = np.linspace(5.0, 90.0, 200)  # inside the excited band 2–100 Hz
    r = model.frequency_response(f) / truth.frequency_response(f)
    return float(np.max(np.abs(20 * np.log10(np.abs(r))))), float(
        np.max(np.abs(np.angle(r, deg=True))))


def test_vocabulary():
    assert METHODS == ("arx", "armax", "oe", "rels", "rml")


@pytest.mark.parametrize("method", METHODS)
def test_every_method_recovers_noise_free_arx(rng, method):
    a, b, _ = system(2)
    u, y, _ = armax_data(rng, a, b, None, 3000)
    m = estimate(u, y, method=method, na=2, nb=1, nc=0, dt=DT_S)
    # noise-free ARX data: every estimator's optimum is the truth; recursive ones reach
    # it to ~1e-6 after 3000 samples from the batch start, batch ones to rounding
    assert_allclose(m.a, a, atol=1e-5)
    assert_allclose(m.b, b, atol=1e-5)


def test_oe_ignores_nc_and_returns_c_equal_a(rng):
    a, b, _ = system(2)
    u, y, _ = armax_data(rng, a, b, None, 2000)
    m = estimate(u, y, method="oe", na=2, nb=1, nc=5, dt=DT_S)
    assert m.nc == 2 and np.array_equal(m.a, m.c)


@pytest.mark.slow
def test_rml_from_batch_start_converges_on_every_seed_where_zero_start_stalls():
    # Output-error records (white sensor noise, 30 dB) of the 4th-order system: the
    # ARMAX noise model needs C = A with roots at radius 0.9875. RML from θ = 0,
    # P(0) = αI stalls far from the truth; started from the batch estimate with its
    # inverse information as P(0) it stays at the prediction-error optimum.
    a, b, _ = system(4)
    truth = ArmaxModel(a=a, b=b, c=a, delay=1, dt=DT_S)
    stalled = 0
    for seed in range(20):
        rng = np.random.default_rng(seed)
        u, y0, _ = armax_data(rng, a, b, None, 4000)
        y = y0 + np.std(y0) * 10 ** (-30 / 20) * rng.standard_normal(y0.size)
        kw = {"method": "rml", "na": 4, "nb": b.size - 1, "nc": 4, "dt": DT_S}
        db, deg = _frf_error(estimate(u, y, init="batch", **kw), truth)
        # converged = within the acceptance of an identified loop, 1 dB / 5° (N = 4000 at
        # 30 dB puts the PEM optimum itself up to ~0.5 dB / 2° from the truth here)
        assert db < 1.0 and deg < 5.0, (seed, db, deg)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", EhssWarning)  # a stalled model may be unstable
            zdb, zdeg = _frf_error(estimate(u, y, init="zero", **kw), truth)
        stalled += zdb > 1.0 or zdeg > 5.0
    # the comparison can fail: the paper's zero start misses on most of these seeds
    assert stalled >= 15


def test_batch_start_records_its_origin(rng):
    a, b, c = system(2)
    u, y, _ = armax_data(rng, a, b, c, 3000, snr_db=30.0)
    m = estimate(u, y, method="rels", na=2, nb=1, nc=1, dt=DT_S)
    assert m.meta["init"] == "batch" and m.meta["start_method"] == "armax_pem"
    m0 = estimate(u, y, method="rels", na=2, nb=1, nc=1, dt=DT_S, init="zero", p0=1e4)
    assert "init" not in m0.meta and m0.meta["p0"] == 1e4


@pytest.mark.parametrize("kw,match", [
    ({"method": "els"}, r"method='els' must be one of 'arx', 'armax', 'oe', 'rels', 'rml'"),
    ({"method": "rml", "init": "warm"}, r"init='warm' must be one of 'batch', 'zero'"),
    ({"method": "arx", "na": 0}, r"na=0 must be an integer in \[1, inf\)"),
    ({"method": "rels", "forgetting": 1.5}, r"forgetting=1.5 must be in \(0, 1\]"),
])
def test_bad_method_or_init(rng, kw, match):
    u = rng.standard_normal(100)
    with pytest.raises(ParameterError, match=match):
        estimate(u, u, **{"na": 1, "nb": 0, "nc": 0, **kw})


@pytest.mark.parametrize("kw,match", [
    ({"method": 3}, r"method=3 must be one of .*, not int"),
    ({"method": "rml", "init": None}, r"init=None must be one of .*, not NoneType"),
    ({"method": "armax", "nb": 1.0}, r"nb=1.0 must be an integer, not float"),
    ({"method": "rels", "p0": "1e6"}, r"p0='1e6' must be a real number, not str"),
])
def test_wrong_types_raise_type_error(rng, kw, match):
    u = rng.standard_normal(100)
    with pytest.raises(TypeError, match=match):
        estimate(u, u, **{"na": 1, "nb": 0, "nc": 0, **kw})


def test_unstable_arx_fit_warns(rng):
    from scipy.signal import lfilter

    u = rng.standard_normal(300)
    y = lfilter([0.0, 1.0], [1.0, -1.02], u)
    with pytest.warns(EhssWarning, match="unstable"):
        m = estimate(u, y, method="arx", na=1, nb=0, nc=0)
    assert m.meta["stable"] is False
