"""Prediction-error minimisation: ARMAX and output-error models against known systems."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.signal import lfilter

from ehss.errors import EhssWarning, ParameterError
from ehss.identification.model import ArmaxModel
from ehss.identification.pem import armax_pem, oe_pem

from .systems import DT_S, armax_data, system


def _frf_error(model, truth, f_lo=5.0, f_hi=90.0):
    """Largest gain (dB) and phase (deg) error over the excited band 2–100 Hz (inside)."""
    f = np.linspace(f_lo, f_hi, 200)
    r = model.frequency_response(f) / truth.frequency_response(f)
    return float(np.max(np.abs(20 * np.log10(np.abs(r))))), float(
        np.max(np.abs(np.angle(r, deg=True))))


def _oe_record(rng, order, n, snr_db=30.0):
    a, b, _ = system(order)
    u, y0, _ = armax_data(rng, a, b, None, n)
    y = y0 + np.std(y0) * 10 ** (-snr_db / 20) * rng.standard_normal(n)
    return u, y, ArmaxModel(a=a, b=b, c=a, delay=1, dt=DT_S)


def test_armax_pem_exact_on_noise_free_arx_data(rng):
    a, b, _ = system(4)
    u, y, _ = armax_data(rng, a, b, None, 4000)
    m = armax_pem(u, y, na=4, nb=b.size - 1, nc=1, dt=DT_S)
    # the ARX start is the exact optimum (zero loss); least squares with condition ~1e4
    assert_allclose(m.a, a, atol=1e-8)
    assert_allclose(m.b, b, atol=1e-8)
    # (C is not identifiable from zero prediction errors: ε = 0/C = 0 for any C)
    assert m.meta["method"] == "armax_pem" and m.meta["stable"]


@pytest.mark.parametrize("order", [2, 4, 6])
def test_armax_pem_recovers_armax_systems(rng, order):
    a, b, c = system(order)
    u, y, nv = armax_data(rng, a, b, c, 8000, snr_db=30.0)
    m = armax_pem(u, y, na=order, nb=b.size - 1, nc=c.size - 1, dt=DT_S)
    db, deg = _frf_error(m, ArmaxModel(a=a, b=b, c=c, delay=1, dt=DT_S))
    # 30 dB SNR and N = 8000 give a standard error of the FRF of a few hundredths of a dB
    # at these orders; 0.5 dB / 3° is the accuracy the identification is asked for
    assert db < 0.5 and deg < 3.0
    # C standard error ~ 1/sqrt(N) ≈ 0.011: 4σ
    assert_allclose(m.c, c, atol=0.045)
    assert_allclose(m.noise_variance, nv, rtol=0.1)  # 3σ of a variance from N = 8000 is 5 %
    assert m.covariance.shape == (m.theta.size, m.theta.size)


@pytest.mark.parametrize("order", [2, 4])
def test_oe_pem_recovers_output_error_systems(rng, order):
    u, y, truth = _oe_record(rng, order, 8000)
    m = oe_pem(u, y, nf=order, nb=truth.nb, dt=DT_S)
    db, deg = _frf_error(m, truth)
    assert db < 0.5 and deg < 3.0
    # one model type: A y = B u + A e is y = B/F u + e
    assert np.array_equal(m.a, m.c) and m.meta["method"] == "oe_pem"
    assert m.is_stable()
    # the minimised loss is at most the truth's (the truth is one candidate θ)
    eps = y - truth.simulate(u)
    assert m.noise_variance <= float(np.mean(eps[order:] ** 2)) * (1 + 1e-9) * (
        (y.size - order) / (y.size - order - 2 * order - 1))


def test_armax_with_c_equal_a_matches_output_error(rng):
    # nc = na: the output-error start makes ARMAX PEM find the OE optimum (RELS/ELS do not)
    u, y, truth = _oe_record(rng, 4, 6000)
    m = armax_pem(u, y, na=4, nb=truth.nb, nc=4, dt=DT_S)
    db, deg = _frf_error(m, truth)
    assert db < 0.5 and deg < 3.0


def test_unstable_estimate_is_flagged_and_warned(rng):
    # a slowly diverging first-order system: the best model is unstable, and says so
    u = rng.standard_normal(400)
    y = lfilter([0.0, 1.0], [1.0, -1.01], u) + 0.01 * rng.standard_normal(400)
    with pytest.warns(EhssWarning, match="unstable"):
        m = armax_pem(u, y, na=1, nb=0, nc=1)
    assert m.meta["stable"] is False and m.meta["max_pole_radius"] > 1.0


def test_scaling_does_not_change_the_model(rng):
    a, b, c = system(2)
    u, y, _ = armax_data(rng, a, b, c, 3000, snr_db=30.0)
    m1 = oe_pem(u, y, nf=2, nb=1, dt=DT_S)
    m2 = oe_pem(1e3 * u, 1e-3 * y, nf=2, nb=1, dt=DT_S)
    # internal RMS scaling: the same optimum up to the solver's tolerance (1e-10 on θ)
    assert_allclose(m2.a, m1.a, atol=1e-6)
    assert_allclose(m2.b * 1e6, m1.b, rtol=1e-5)


@pytest.mark.parametrize("kw,match", [
    ({"radius": 1.0}, r"radius=1.0 must be in \(0, 1\)"),
    ({"radius": 0.0}, r"radius=0.0 must be in \(0, 1\)"),
    ({"max_nfev": 0}, r"max_nfev=0 must be an integer in \[1, inf\)"),
    ({"nb": -1}, r"nb=-1 must be an integer in \[0, inf\)"),
    ({"tol": -1e-3}, r"tol=-0.001 must be in \[0, inf\)"),
])
def test_bad_settings(rng, kw, match):
    u = rng.standard_normal(200)
    args = {"nf": 1, "nb": 0, **kw}
    with pytest.raises(ParameterError, match=match):
        oe_pem(u, u, **args)
    arma = {"na": 1, "nb": 0, "nc": 1, **kw}
    with pytest.raises(ParameterError, match=match):
        armax_pem(u, u, **arma)


@pytest.mark.parametrize("kw,match", [
    ({"radius": "0.9"}, r"radius='0.9' must be a real number, not str"),
    ({"max_nfev": 10.0}, r"max_nfev=10.0 must be an integer, not float"),
    ({"nb": None}, r"nb=None must be an integer, not NoneType"),
])
def test_wrong_types_raise_type_error(rng, kw, match):
    u = rng.standard_normal(200)
    with pytest.raises(TypeError, match=match):
        oe_pem(u, u, **{"nf": 1, "nb": 0, **kw})
    with pytest.raises(TypeError, match=match):
        armax_pem(u, u, **{"na": 1, "nb": 0, "nc": 1, **kw})


def test_schur_cohn_stability_test_matches_roots(rng):
    from ehss.identification.pem import _inside

    for _ in range(3000):
        n = int(rng.integers(1, 8))
        p = rng.standard_normal(n) * rng.uniform(0.1, 2.0)
        r = float(rng.uniform(0.5, 0.9999))
        radius = float(np.max(np.abs(np.roots(np.concatenate([[1.0], p])))))
        if abs(radius - r) < 1e-9:  # undecidable in floating point at the boundary
            continue
        assert _inside(p, r) == (radius < r), (p, r, radius)


def _oversampled_plant(order, fs, f_bw=1.0):
    """Resonances (ζ = 0.3) spread over the bandwidth f_bw, unit DC gain, delay 1."""
    from .systems import resonance_poles

    freqs = {2: [f_bw], 4: [0.4 * f_bw, f_bw], 6: [0.3 * f_bw, 0.7 * f_bw, 1.2 * f_bw]}[order]
    a = np.real(np.poly([p for f in freqs for p in resonance_poles(f, 0.3, fs)]))
    b = np.array([1.0, 0.5]) * a.sum() / 1.5
    return a, b


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["oe", "armax"])
@pytest.mark.parametrize("order", [2, 4, 6])
@pytest.mark.parametrize("oversampling", [10, 100])
def test_oversampled_records_identify_within_half_a_db(kind, order, oversampling):
    from ehss.identification import estimate

    from .systems import band_limited

    f_bw = 1.0
    fs = oversampling * f_bw
    a, b = _oversampled_plant(order, fs, f_bw)
    rng = np.random.default_rng(1000 * order + oversampling)
    n = 10_000
    u = band_limited(rng, n, f_lo=0.02 * f_bw, f_hi=min(2 * f_bw, 0.45 * fs), fs=fs)
    y0 = lfilter(np.r_[0.0, b], a, u)
    if kind == "oe":  # white sensor noise, 30 dB SNR
        c = a
        y = y0 + np.std(y0) * 10 ** (-30 / 20) * rng.standard_normal(n)
    else:  # coloured equation noise C/A e, 30 dB SNR
        c = np.real(np.poly([0.5] * (order // 2)))
        v = lfilter(c, a, rng.standard_normal(n))
        y = y0 + v * np.std(y0) / np.std(v) * 10 ** (-30 / 20)
    m = estimate(u, y, method=kind, na=order, nb=1, nc=c.size - 1, dt=1.0 / fs)
    truth = ArmaxModel(a=a, b=b, c=c, delay=1, dt=1.0 / fs)
    f = np.linspace(0.05 * f_bw, 2.0 * f_bw, 200)  # the excited band
    r = m.frequency_response(f) / truth.frequency_response(f)
    # 0.5 dB / 3° is the accuracy asked of the default estimators at 30 dB SNR; the
    # statistical error at N = 1e4 is below 0.25 dB / 1.5° in every case here
    assert np.max(np.abs(20 * np.log10(np.abs(r)))) < 0.5
    assert np.max(np.abs(np.angle(r, deg=True))) < 3.0
    assert m.is_stable()


# ------------------------------------------------------- compiled residuals and Jacobians
def _reference_armax_errors(theta, u, y, na, nb, nc, d):
    """ε = (A y − q^-d B u)/C with scipy's lfilter (direct form II transposed), at rest."""
    a = np.concatenate([[1.0], theta[:na]])
    bd = np.concatenate([np.zeros(d), theta[na : na + nb + 1]])
    c = np.concatenate([[1.0], theta[na + nb + 1 :]])
    return lfilter([1.0], c, lfilter(a, [1.0], y) - lfilter(bd, [1.0], u))


def _reference_oe_output(theta, u, nf, nb, d):
    return lfilter(np.concatenate([np.zeros(d), theta[nf:]]),
                   np.concatenate([[1.0], theta[:nf]]), u)


def _stable_monic(rng, n, radius):
    """Coefficients [p1..pn] of a monic polynomial with roots of modulus < radius."""
    roots = []
    while len(roots) < n:
        r, w = rng.uniform(0.2, radius), rng.uniform(0.1, 3.0)
        if n - len(roots) >= 2:
            roots += [r * np.exp(1j * w), r * np.exp(-1j * w)]
        else:
            roots.append(r * rng.choice([-1.0, 1.0]))
    return np.real(np.poly(roots))[1:]


def _central_differences(fun, theta, h_rel=1e-6):
    cols = []
    for i in range(theta.size):
        h = h_rel * max(1.0, abs(theta[i]))
        tp, tm = theta.copy(), theta.copy()
        tp[i] += h
        tm[i] -= h
        cols.append((fun(tp) - fun(tm)) / (2 * h))
    return np.column_stack(cols)


@pytest.mark.parametrize("na,nb,nc,d", [(1, 0, 1, 0), (2, 1, 1, 1), (4, 3, 2, 3), (2, 2, 4, 2)])
def test_compiled_armax_residuals_and_jacobian_match_a_plain_reference(rng, na, nb, nc, d):
    from ehss.identification import _pem_kernels as pk

    n = 3000
    u, y = rng.standard_normal(n), rng.standard_normal(n)
    theta = np.concatenate([_stable_monic(rng, na, 0.95), rng.standard_normal(nb + 1),
                            _stable_monic(rng, nc, 0.9)])
    k0 = max(na, nb + d, nc)
    eps = pk.armax_errors(theta, u, y, na, nb, nc, d)
    ref = _reference_armax_errors(theta, u, y, na, nb, nc, d)
    # two orderings of the same sums: rounding differences of a few ulp, amplified by
    # 1/C (roots within 0.9: at most ~1/(1-0.9)^nc = 100x): 1e-11 of the signal's size
    assert_allclose(eps, ref, rtol=0, atol=1e-11 * np.max(np.abs(ref)))
    J = pk.armax_jacobian(theta, u, y, eps, na, nb, nc, d, k0)
    Jfd = _central_differences(
        lambda th: _reference_armax_errors(th, u, y, na, nb, nc, d)[k0:], theta)
    # central differences with h = 1e-6: truncation O(h²) ~ 1e-12 times the third
    # derivative (ε is polynomial in a, b; 1/C's derivatives grow by ~1/(1-0.9) per
    # order), rounding O(ulp·|ε|/h) ~ 1e-10 of |ε|: agreement to 1e-6 of the column
    # scale is far above both, and far below any wrong term (those are O(1))
    scale = np.max(np.abs(Jfd), axis=0)
    assert np.all(np.abs(J - Jfd) <= 1e-6 * scale)


@pytest.mark.parametrize("nf,nb,d", [(1, 0, 0), (2, 1, 1), (4, 3, 2)])
def test_compiled_oe_output_and_jacobian_match_a_plain_reference(rng, nf, nb, d):
    from ehss.identification import _pem_kernels as pk

    n = 3000
    u, y = rng.standard_normal(n), rng.standard_normal(n)
    theta = np.concatenate([_stable_monic(rng, nf, 0.95), rng.standard_normal(nb + 1)])
    k0 = max(nf, nb + d)
    yhat = pk.oe_simulate(theta, u, nf, nb, d)
    ref = _reference_oe_output(theta, u, nf, nb, d)
    # as for ARMAX: a few ulp through 1/F with roots within 0.95 (≤ 20x per order)
    assert_allclose(yhat, ref, rtol=0, atol=1e-10 * np.max(np.abs(ref)))
    J = pk.oe_jacobian(theta, u, yhat, nf, nb, d, k0)
    Jfd = _central_differences(lambda th: (y - _reference_oe_output(th, u, nf, nb, d))[k0:],
                               theta)
    scale = np.max(np.abs(Jfd), axis=0)
    assert np.all(np.abs(J - Jfd) <= 1e-6 * scale)  # as for ARMAX


def test_a_neighbour_start_can_only_lower_the_loss(rng):
    from ehss.identification._grid import padded_theta

    a, b, c = system(4)
    u, y, _ = armax_data(rng, a, b, c, 6000, snr_db=25.0)
    small = armax_pem(u, y, na=2, nb=1, nc=1, dt=DT_S)
    theta0 = padded_theta(small, 3, 1, 1)
    padded = ArmaxModel.from_theta(theta0, na=3, nb=1, nc=1, delay=1, dt=DT_S)
    # zero-padding writes the same model: the same predictions to the last bit but for
    # the order of the sums (a few ulp)
    assert_allclose(padded.predict(u, y), small.predict(u, y), rtol=0,
                    atol=1e-12 * np.max(np.abs(y)))
    plain = armax_pem(u, y, na=3, nb=1, nc=1, dt=DT_S)
    started = armax_pem(u, y, na=3, nb=1, nc=1, dt=DT_S, theta0=theta0)
    assert set(started.meta["starts"]) == set(plain.meta["starts"]) | {"theta0"}
    best = min(started.meta["starts"].values())
    # the winner is the best start: no worse than without the start, no worse than the
    # neighbour (which the start reproduces, and LM only accepts steps that lower the loss)
    loss = started.meta["starts"][started.meta["start"]]
    assert loss == best
    assert loss <= min(plain.meta["starts"].values())
    # the neighbour's loss is a mean over k ≥ 2, this one's over k ≥ 3: the sum over
    # fewer samples is no larger, the mean at most (N − 2)/(N − 3) times (+ rounding)
    n_small = u.size - small.meta["first_sample"]
    n_big = u.size - started.meta["first_sample"]
    small_loss = small.meta["starts"][small.meta["start"]]
    assert loss <= started.meta["starts"]["theta0"] <= small_loss * n_small / n_big * (1 + 1e-9)


def test_theta0_of_the_wrong_size_is_refused(rng):
    u = rng.standard_normal(500)
    with pytest.raises(ParameterError, match=r"theta0 has shape \(2,\), must be \(4,\)"):
        armax_pem(u, u, na=1, nb=1, nc=1, theta0=[0.1, 0.2])
    with pytest.raises(ParameterError, match=r"theta0=.* must be finite"):
        armax_pem(u, u, na=1, nb=1, nc=1, theta0=[0.1, 0.2, np.nan, 0.0])
    with pytest.raises(TypeError, match=r"theta0=.* must be a sequence of real numbers"):
        armax_pem(u, u, na=1, nb=1, nc=1, theta0=["0.1", 0.2, 0.3, 0.0])


def test_the_smaller_c_start_is_the_one_the_order_search_hands_over(rng):
    """armax_pem(smaller_c=True) fits nc − 1 first and starts from it; the order search
    passes that fit as theta0 instead: both must give the same model to the last bit,
    or a refit of the search's pick would not reproduce it."""
    from ehss.identification._grid import padded_theta

    a, b, c = system(2)
    u, y, _ = armax_data(rng, a, b, c, 4000, snr_db=25.0)
    kw = {"na": 2, "nb": 1, "delay": 1, "dt": DT_S}
    one = armax_pem(u, y, nc=1, **kw)
    handed = armax_pem(u, y, nc=2, theta0=padded_theta(one, 2, 1, 2), **kw)
    itself = armax_pem(u, y, nc=2, smaller_c=True, **kw)
    assert np.array_equal(handed.theta, itself.theta)
    assert handed.meta["starts"] == itself.meta["starts"]
    assert "theta0" in itself.meta["starts"]
