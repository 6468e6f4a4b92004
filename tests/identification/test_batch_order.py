"""Batch references (ARX LS, ARMAX ELS) and order selection."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.signal import lfilter

from ehss.errors import DataError, IdentificationError, ParameterError
from ehss.identification.batch import armax_els, arx_ls
from ehss.identification.order import select_order
from ehss.validation import simulation_fit

from .systems import DT_S, armax_data, system


def test_arx_ls_exact_on_noise_free_data(rng):
    a, b, _ = system(4)
    u, y, _ = armax_data(rng, a, b, None, 5000)
    m = arx_ls(u, y, na=4, nb=b.size - 1, delay=1, dt=DT_S)
    # exact regression, lstsq in float64 with condition ~1e4: 1e-9
    assert_allclose(m.a, a, atol=1e-9)
    assert_allclose(m.b, b, atol=1e-9)
    assert m.meta["method"] == "arx_ls"


def test_armax_els_recovers_c_and_noise_variance(rng):
    a, b, c = system(2)
    u, y, nv = armax_data(rng, a, b, c, 20_000, snr_db=20.0)
    m = armax_els(u, y, na=2, nb=b.size - 1, nc=1, delay=1, dt=DT_S)
    # N = 2e4: standard errors of c1 ~ 1/sqrt(N) ≈ 7e-3; 3σ ≈ 2e-2
    assert_allclose(m.c, c, atol=2e-2)
    assert_allclose(m.noise_variance, nv, rtol=3e-2)  # 3σ of a variance estimate, N=2e4
    assert_allclose(m.a, a, atol=2e-3)
    assert m.covariance.shape == (5, 5)
    assert m.meta["method"] == "armax_els" and m.meta["els_iterations"] >= 1


def test_armax_els_is_els_and_pem_improves_on_it(rng):
    """armax_els returns the ELS iterate, not the prediction-error optimum that starts
    from it: its one-step prediction errors (recomputed here with lfilter) are larger."""
    from ehss.identification.pem import armax_pem

    a, b, c = system(2)
    u, y, _ = armax_data(rng, a, b, c, 20_000, snr_db=20.0)
    els = armax_els(u, y, na=2, nb=b.size - 1, nc=1, delay=1, dt=DT_S)
    pem = armax_pem(u, y, na=2, nb=b.size - 1, nc=1, delay=1, dt=DT_S)

    def loss(m):
        e = lfilter([1.0], m.c, lfilter(m.a, [1.0], y) - lfilter(np.r_[0.0, m.b], [1.0], u))
        return float(np.mean(e[2:] ** 2))

    assert els.meta["method"] == "armax_els" and pem.meta["method"] == "armax_pem"
    # PEM minimises this loss from the ELS start (among others): it ends no higher, and
    # ELS (which oscillates at ~1e-4 relative change on this record) is not its optimum
    assert loss(pem) <= loss(els)
    assert np.linalg.norm(pem.theta - els.theta) > 1e-6 * np.linalg.norm(els.theta)


def _fit_on(uv, yv):
    """The validation fit the workflow scores with: free run from the fitted state."""
    return lambda m: simulation_fit(m, uv, yv, initial="estimate")


def test_select_order_prefers_true_order(rng):
    a, b, c = system(2)
    u, y, _ = armax_data(rng, a, b, c, 6000, snr_db=30.0)
    uv, yv, _ = armax_data(rng, a, b, c, 3000, snr_db=30.0)
    sel = select_order(u, y, na=[1, 2, 3], nb=[0, 1], nc=[1], delay=1, dt=DT_S,
                       criterion="mdl", score=_fit_on(uv, yv))
    assert len(sel.table) == 6
    assert (sel.best.na, sel.best.nb) in {(2, 1), (2, 0)}
    assert sel.best.fit > 90.0
    row = sel.table[0]
    assert row.n_params == row.na + row.nb + 1 + row.nc
    assert sel.model.na == sel.best.na


def test_select_order_does_not_depend_on_the_number_of_threads(rng):
    a, b, c = system(2)
    u, y, _ = armax_data(rng, a, b, c, 4000, snr_db=30.0)
    kw = {"na": [1, 2, 3], "nb": [0, 1], "nc": [1, 2], "delay": 1, "dt": DT_S}
    one = select_order(u, y, jobs=1, **kw)
    two = select_order(u, y, jobs=2, **kw)
    # every fit depends on its data and its starts only (a candidate waits for its
    # smaller neighbours whatever the threads): the same numbers to the last bit
    assert one.table == two.table
    assert np.array_equal(one.model.theta, two.model.theta)


def test_select_order_with_rels(rng):
    a, b, c = system(4)
    u, y, _ = armax_data(rng, a, b, c, 8000, snr_db=30.0)
    sel = select_order(u, y, na=[2, 4], nb=[1, 2], nc=[2], delay=1, dt=DT_S,
                       criterion="aic", method="rels", init="zero", p0=1e10, p0_c=1e2)
    assert (sel.best.na, sel.best.nb) == (4, 2)
    assert sel.model.meta["p0_c"] == 1e2
    assert sel.method == "rels"


def test_select_order_defaults_to_validation_fit_with_the_armax_estimator(rng):
    a, b, c = system(2)
    u, y, _ = armax_data(rng, a, b, c, 4000, snr_db=30.0)
    uv, yv, _ = armax_data(rng, a, b, c, 2000, snr_db=30.0)
    sel = select_order(u, y, na=[1, 2, 3], nb=[1], nc=[1], delay=1, dt=DT_S,
                       score=_fit_on(uv, yv))
    assert sel.criterion == "fit" and sel.method == "armax"
    assert sel.model.meta["method"] == "armax_pem"
    # the pick is the smallest candidate within 0.1 point of the highest validation fit
    assert sel.best.fit >= max(r.fit for r in sel.table) - 0.1
    assert all(r.stable and r.max_pole_radius < 1 for r in sel.table)
    assert (sel.best.na, sel.best.nb) == (2, 1)


def test_select_order_picks_among_admissible_candidates_when_any_is(rng):
    # the true orders (2, 1) fit best; declared inadmissible (as a model failing the
    # acceptance would be), the pick is the best of the admissible rest; when none is
    # admissible, the pick is the ordinary one
    a, b, c = system(2)
    u, y, _ = armax_data(rng, a, b, c, 4000, snr_db=30.0)
    uv, yv, _ = armax_data(rng, a, b, c, 2000, snr_db=30.0)
    kw = dict(na=[1, 2, 3], nb=[1], nc=[1], delay=1, dt=DT_S, score=_fit_on(uv, yv))
    plain = select_order(u, y, **kw)
    assert (plain.best.na, plain.best.nb) == (2, 1)
    picky = select_order(u, y, **kw, admissible=lambda m: m.na != 2)
    rest = [r for r in picky.table if r.na != 2]
    assert picky.best.na != 2
    assert picky.best.fit >= max(r.fit for r in rest) - 0.1
    assert picky.model.na == picky.best.na
    none = select_order(u, y, **kw, admissible=lambda m: False)
    assert (none.best.na, none.best.nb) == (2, 1)
    with pytest.raises(TypeError, match="admissible must be callable"):
        select_order(u, y, **kw, admissible=True)


def test_select_order_never_recommends_an_unstable_model(rng):
    # a diverging plant: every least-squares candidate is unstable, so none is picked
    u = rng.standard_normal(400)
    y = lfilter([0.0, 1.0], [1.0, -1.02], u)
    uv = rng.standard_normal(200)
    yv = lfilter([0.0, 1.0], [1.0, -1.02], uv)
    with pytest.raises(IdentificationError, match="none of the 2 candidate orders gives a "
                       "stable model with method 'arx'"):
        select_order(u, y, na=[1, 2], nb=[0], nc=[0], method="arx", score=_fit_on(uv, yv))


def test_select_order_with_rml(rng):
    # output-error record (white noise at the output, ARMAX C = A): RML with nc = na
    a, b, _ = system(2)
    u, y, _ = armax_data(rng, a, b, None, 8000)
    y = y + 0.03 * np.std(y) * rng.standard_normal(y.size)
    sel = select_order(u, y, na=[1, 2], nb=[1], nc=[1, 2], delay=1, dt=DT_S,
                       criterion="aic", method="rml", p0=1e10, p0_c=1e2, forgetting=0.9995)
    assert len(sel.table) == 4
    assert sel.best.na == 2
    assert sel.model.meta["method"] == "rml" and sel.model.meta["forgetting"] == 0.9995


def test_select_order_errors(rng):
    u = rng.standard_normal(300)
    with pytest.raises(ParameterError, match="method='pem' must be one of 'arx', 'armax', "
                       "'oe', 'rels', 'rml'"):
        select_order(u, u, na=[1], nb=[0], nc=[0], method="pem")
    with pytest.raises(ParameterError, match=r"fit_tolerance=-1 must be in \[0, inf\)"):
        select_order(u, u, na=[1], nb=[0], nc=[0], fit_tolerance=-1)
    with pytest.raises(ParameterError, match="init='warm' must be one of 'batch', 'zero'"):
        select_order(u, u, na=[1], nb=[0], nc=[0], method="rml", init="warm")
    with pytest.raises(ParameterError, match="criterion='bic' must be one of"):
        select_order(u, u, na=[1], nb=[0], nc=[0], criterion="bic")
    with pytest.raises(ParameterError, match="criterion='fit' needs a score"):
        select_order(u, u, na=[1], nb=[0], nc=[0], criterion="fit")
    with pytest.raises(TypeError, match="score must be callable"):
        select_order(u, u, na=[1], nb=[0], nc=[0], score=50.0)
    with pytest.raises(ParameterError, match=r"na=\[0\] must hold integers >= 1"):
        select_order(u, u, na=[0], nb=[0], nc=[0])
    # a wrong type is a TypeError, a wrong value a ParameterError
    with pytest.raises(TypeError, match=r"na=\[1.5\] must hold integers >= 1, not float"):
        select_order(u, u, na=[1.5], nb=[0], nc=[0])
    with pytest.raises(TypeError, match=r"method=3 must be one of .*, not int"):
        select_order(u, u, na=[1], nb=[0], nc=[0], method=3)
    with pytest.raises(TypeError, match=r"fit_tolerance='0.1' must be a real number"):
        select_order(u, u, na=[1], nb=[0], nc=[0], fit_tolerance="0.1")
    with pytest.raises(DataError, match=r"y\[3\]=nan is not finite"):
        arx_ls(u, np.r_[u[:3], np.nan, u[4:]], na=1, nb=0)
