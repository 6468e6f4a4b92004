"""RelsEstimator's forgetting factor switched while it runs (variable forgetting)."""

from __future__ import annotations

import numpy as np
import pytest

from ehss.errors import ParameterError
from ehss.identification.rels import RelsEstimator

from .naive import naive_rels
from .test_kernel import _assert_close_to_exact, _record

#: (first sample, λ from there on): a long memory, a short one, the long one again
SCHEDULE = ((0, 0.999), (300, 0.98), (550, 0.999))


def _lambdas(n: int) -> np.ndarray:
    lam = np.empty(n)
    for start, value in SCHEDULE:
        lam[start:] = value
    return lam


def _switched(u, y, **kw):
    """The streaming estimator run over u, y with λ switched as SCHEDULE says, a block
    per λ, its last sample through update(): the switch comes with that sample's (22)
    still pending."""
    est = RelsEstimator(forgetting=SCHEDULE[0][1], **kw)
    err = []
    stops = [start for start, _ in SCHEDULE[1:]] + [u.size]
    for (start, lam), stop in zip(SCHEDULE, stops, strict=True):
        est.set_forgetting(lam)
        err.append(est.update_many(u[start:stop - 1], y[start:stop - 1]))
        err.append([est.update(u[stop - 1], y[stop - 1])])
    return est, np.concatenate(err)


@pytest.mark.parametrize(("orders", "alpha", "trace_bound", "method"), [
    ((4, 2, 2, 1), 1e3, None, "rels"),
    ((3, 2, 0, 0), 1e2, 50.0, "rels"),      # the trace bound active too
    ((6, 5, 6, 1), 1e6, None, "rels"),      # the structure the live compensation runs
    ((3, 1, 2, 1), 1e3, None, "rml"),
])
def test_a_switched_forgetting_matches_the_reference(rng, orders, alpha, trace_bound,
                                                     method):
    # the reference runs (20)-(22) with λ(k) per sample; each switch applies from the
    # sample after it, the pending (22) of the sample before with the λ it was formed with
    na, nb, nc, d = orders
    u, y = _record(rng, "band-limited", 800)
    kw = dict(na=na, nb=nb, nc=nc, delay=d, alpha=alpha, trace_bound=trace_bound,
              method=method)
    ref = naive_rels(u, y, lam=_lambdas(u.size), **kw)
    exact = naive_rels(u, y, lam=_lambdas(u.size), **kw, dtype=np.longdouble)
    est, err = _switched(u, y, na=na, nb=nb, nc=nc, delay=d, p0=alpha,
                         trace_bound=trace_bound, method=method)
    assert est.forgetting == SCHEDULE[-1][1]
    _assert_close_to_exact(err, ref[2], exact[2], "e")
    _assert_close_to_exact(est.theta, ref[0], exact[0], "theta")
    _assert_close_to_exact(est.P, ref[1], exact[1], "P")
    counters = est.counters
    for key in ("resets", "c_projections", "trace_scalings"):
        assert counters[key] == ref[4][key] == exact[4][key], key
    assert np.array_equal(est.P, est.P.T)


def test_the_schedule_matters(rng):
    # the comparison can fail: the same estimator left at its first λ throughout is far
    # outside the bound of the switched reference
    u, y = _record(rng, "band-limited", 800)
    kw = dict(na=4, nb=2, nc=2, delay=1, alpha=1e3)
    ref = naive_rels(u, y, lam=_lambdas(u.size), **kw)
    exact = naive_rels(u, y, lam=_lambdas(u.size), **kw, dtype=np.longdouble)
    held = RelsEstimator(na=4, nb=2, nc=2, delay=1, p0=1e3, forgetting=SCHEDULE[0][1])
    held.update_many(u, y)
    with pytest.raises(AssertionError, match="kernel error"):
        _assert_close_to_exact(held.theta, ref[0], exact[0], "theta")


def test_switching_back_and_forth_at_one_sample_changes_nothing(rng):
    u, y = _record(rng, "white", 400)
    kw = dict(na=2, nb=1, nc=1, delay=1, p0=1e3, forgetting=0.99)
    ref, est = RelsEstimator(**kw), RelsEstimator(**kw)
    ref.update_many(u, y)
    est.update_many(u[:200], y[:200])
    est.set_forgetting(0.9)
    est.set_forgetting(0.99)
    est.update_many(u[200:], y[200:])
    # the pending (22) applied apart from the next gain: the same operations but for
    # the rounding of g = P r formed after P instead of beside it
    np.testing.assert_allclose(est.theta, ref.theta, rtol=1e-9)


@pytest.mark.parametrize(("value", "error", "message"), [
    (0.0, ParameterError, r"forgetting=0.0 must be in \(0, 1\]"),
    (1.5, ParameterError, r"forgetting=1.5 must be in \(0, 1\]"),
    (float("nan"), ParameterError, "forgetting=nan must be finite"),
    ("0.99", TypeError, "forgetting='0.99' must be a real number"),
])
def test_a_bad_forgetting_is_refused_and_nothing_changes(rng, value, error, message):
    u, y = _record(rng, "white", 200)
    est = RelsEstimator(na=2, nb=1, nc=1, delay=1, p0=1e3, forgetting=0.99)
    est.update_many(u, y)
    P, theta = est.P, est.theta
    with pytest.raises(error, match=message):
        est.set_forgetting(value)
    assert est.forgetting == 0.99
    np.testing.assert_array_equal(est.P, P)
    np.testing.assert_array_equal(est.theta, theta)
