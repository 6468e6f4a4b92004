"""RelsBank and rels_multichannel: each channel is the single-channel estimator.

Channel c of a bank runs the same per-sample step as the single-channel loop, in the
same operation order, so its results equal a single-channel run's; they are compared
to 1e-12 relative (they agree bit for bit; the tolerance only allows a compiler that
orders the same operations differently in the two compiled loops), and each channel
against the independent numpy reference with the bounds of test_kernel.py.
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from ehss.errors import DataError, ParameterError
from ehss.identification import RelsSettings
from ehss.identification import _bank_kernels as B
from ehss.identification._common import block_counters, start_state
from ehss.identification.bank import RelsBank, rels_multichannel
from ehss.identification.rels import RelsEstimator, rels

from .naive import naive_rels
from .systems import kernel_settings
from .test_kernel import _assert_close_to_exact, _record

#: one set of orders for every bank here: the bank loop compiles once (seconds)
ORDERS = dict(na=3, nb=1, nc=2, delay=1)


def _channels(rng, n_samples=800):
    """Three channels of different kinds: band-limited, white, band-limited."""
    records = [_record(rng, kind, n_samples) for kind in ("band-limited", "white",
                                                          "band-limited")]
    return (np.column_stack([r[0] for r in records]),
            np.column_stack([r[1] for r in records]))


@pytest.mark.slow
@pytest.mark.parametrize(("lam", "method"), [(1.0, "rels"), (0.99, "rels"), (0.995, "rml")])
def test_bank_channels_match_reference(rng, lam, method):
    na, nb, nc, d = ORDERS.values()
    n = na + nb + 1 + nc
    u, y = _channels(rng)
    settings = kernel_settings(na, nb, nc, d, lam, 1e4, 1e2, 1e4 * (na + nb + 1) + 1e2 * nc,
                         0.99, method)
    blocks = B.new_blocks(settings, u.shape[1])
    views = [start_state(blocks[c], settings, np.zeros(n)) for c in range(u.shape[1])]
    rec = B.bank_record(u, y)
    assert B.bank_kernel(na, nb, nc, d)(blocks, rec, True) == u.shape[0]
    for c in range(u.shape[1]):
        kw = dict(na=na, nb=nb, nc=nc, delay=d, lam=lam, alpha=1e4, alpha_c=1e2,
                  method=method)
        ref = naive_rels(u[:, c], y[:, c], **kw)
        exact = naive_rels(u[:, c], y[:, c], **kw, dtype=np.longdouble)
        for got, i, name in ((views[c].theta, 0, "theta"), (views[c].P, 1, "P"),
                             (rec[2, :, c], 2, "e"), (rec[3, :, c], 3, "xi")):
            _assert_close_to_exact(got, ref[i], exact[i], f"channel {c} {name}")
        counters = block_counters(blocks[c])
        for key in ("resets", "c_projections", "trace_scalings"):
            assert counters[key] == ref[4][key], key


@pytest.mark.slow
@pytest.mark.parametrize("method", ["rels", "rml"])
def test_rels_multichannel_equals_rels_per_channel(rng, method):
    u, y = _channels(rng)
    u = u * np.array([1.0, 3e3, 0.02])  # each channel scaled by its own RMS
    models = rels_multichannel(u, y, **ORDERS, forgetting=0.995, method=method)
    for c, got in enumerate(models):
        want = rels(u[:, c], y[:, c], **ORDERS, forgetting=0.995, method=method)
        assert_allclose(got.theta, want.theta, rtol=1e-12, atol=0)
        assert_allclose(got.covariance, want.covariance, rtol=1e-12, atol=0)
        assert got.noise_variance == pytest.approx(want.noise_variance, rel=1e-12)
        for key in ("resets", "c_projections", "trace_scalings", "u_scale", "y_scale"):
            assert got.meta[key] == want.meta[key]
        assert got.meta["channel"] == c


@pytest.mark.slow
def test_bank_streams_as_single_estimators(rng):
    # per-channel scales, sample by sample, then a block: the errors, θ̂, counters and
    # models of RelsEstimators with the same settings
    u, y = _channels(rng, 600)
    scales = [1.0, 2.0, 0.5]
    bank = RelsBank(n_channels=3, **ORDERS, forgetting=0.99, u_scale=scales, y_scale=2.0)
    singles = [RelsEstimator(**ORDERS, forgetting=0.99, u_scale=s, y_scale=2.0)
               for s in scales]
    got = np.array([bank.update(u[k], y[k]) for k in range(300)])
    want = np.array([[e.update(float(u[k, c]), float(y[k, c]))
                      for c, e in enumerate(singles)] for k in range(300)])
    assert_allclose(got, want, rtol=1e-12, atol=0)
    got = bank.update_many(u[300:], y[300:])
    want = np.column_stack([e.update_many(u[300:, c], y[300:, c])
                            for c, e in enumerate(singles)])
    assert_allclose(got, want, rtol=1e-12, atol=0)
    assert_allclose(bank.theta, [e.theta for e in singles], rtol=1e-12, atol=0)
    assert bank.counters == [e.counters for e in singles]
    for c, e in enumerate(singles):
        assert_allclose(bank.model(c).c, e.model.c, rtol=1e-12, atol=0)
    bank.reset()
    assert np.all(bank.theta == 0.0) and bank.counters[0]["n_samples"] == 0


@pytest.mark.slow
def test_bank_refuses_bad_samples_and_keeps_state(rng):
    bank = RelsBank(n_channels=2, **ORDERS)
    bank.update([1.0, 2.0], [0.5, 0.1])
    theta = bank.theta
    with pytest.raises(DataError, match="finite"):
        bank.update([1.0, np.nan], [0.0, 0.0])
    with pytest.raises(ValueError):
        bank.update([1.0, 2.0, 3.0], [0.0, 0.0, 0.0])  # three samples for two channels
    with pytest.raises(DataError, match="channels"):
        bank.update_many(np.ones((5, 3)), np.ones((5, 3)))
    assert np.array_equal(bank.theta, theta)
    assert bank.counters[0]["n_samples"] == 1
    with pytest.raises(ParameterError, match="channel"):
        bank.model(2)


@pytest.mark.parametrize(("u", "y", "message"), [
    (np.ones(50), np.ones(50), "n_samples, n_channels"),
    (np.ones((50, 2)), np.ones((50, 3)), "n_samples, n_channels"),
    (np.ones((5, 2)), np.ones((5, 2)), "too few"),
])
def test_rels_multichannel_bad_data(u, y, message):
    with pytest.raises(DataError, match=message):
        rels_multichannel(u, y, **ORDERS)


def test_bank_bad_settings():
    with pytest.raises(ParameterError, match="n_channels"):
        RelsBank(n_channels=0, **ORDERS)
    with pytest.raises(ParameterError, match="u_scale"):
        RelsBank(n_channels=2, **ORDERS, u_scale=[1.0, -1.0])
    with pytest.raises(TypeError, match=r"n_channels=2.0 must be an integer, not float"):
        RelsBank(n_channels=2.0, **ORDERS)
    with pytest.raises(TypeError, match=r"y_scale='1' must be a real number, not str"):
        RelsBank(n_channels=2, **ORDERS, y_scale=[1.0, "1"])
    with pytest.raises(TypeError, match=r"nc=1.0 must be an integer, not float"):
        RelsBank(n_channels=2, **{**ORDERS, "nc": 1.0})
    with pytest.raises(TypeError, match="not both"):
        RelsBank(n_channels=2, settings=RelsSettings(**ORDERS), na=3)


def test_bank_takes_settings_as_an_object(rng):
    u, y = _channels(rng, 300)
    settings = RelsSettings(**ORDERS, forgetting=0.99)
    by_object = rels_multichannel(u, y, settings=settings)
    by_keywords = rels_multichannel(u, y, **ORDERS, forgetting=0.99)
    for a, b in zip(by_object, by_keywords, strict=True):
        assert np.array_equal(a.theta, b.theta) and a.meta == b.meta
    bank = RelsBank(n_channels=3, settings=settings)
    assert bank.settings is settings
    assert np.array_equal(bank.update_many(u, y), RelsBank(
        n_channels=3, **ORDERS, forgetting=0.99).update_many(u, y))
