"""Extended least squares through the Gram matrix against ``numpy.linalg.lstsq``.

:func:`ehss.identification.batch.gram_lstsq` solves the regression from [−Φ t]ᵀ[−Φ t]
(Cholesky) when Φ, its columns scaled to unit norm, has a condition number κ up to
``_COND_GRAM``, and by ``lstsq`` of the formed Φ above it. Through the normal equations
the relative error of θ is of order ε κ² (ε = 2.2e-16), through an SVD of order ε κ;
each path is checked here against ``lstsq`` of Φ formed by
:func:`~ehss.identification._common.regression_matrix`, to that bound, on a
well-conditioned ARMAX record and on an oversampled 6th-order one (κ far above the
threshold) and one near it (κ ≈ 1e4, still through ΦᵀΦ); and the whole ELS iteration
against one written with ``lstsq``. Also the prediction-error fit's one-pass filter
kernel against the two kernels it fuses.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

from ehss.identification import _pem_kernels as pk
from ehss.identification._common import prediction_errors, regression_matrix, stabilise
from ehss.identification.batch import _COND_GRAM, els_theta, gram_lstsq

from .systems import band_limited, resonance_poles

EPS = np.finfo(float).eps


def _record(rng, oversampled):
    """A 4th-order loop sampled at 6 Hz and driven by white noise, or a 6th-order one
    (resonances at 0.3, 0.7 and 1.2 Hz, ζ 0.3) sampled at 1 kHz and driven by noise
    band-limited to 0.02–1 Hz; C = 1 − 0.5 q⁻¹, 30 dB SNR, 6000 samples, unit RMS."""
    n = 6000
    fs = 1000.0 if oversampled else 6.0
    freqs = (0.3, 0.7, 1.2) if oversampled else (0.4, 1.0)
    a = np.real(np.poly(sum((resonance_poles(f, 0.3, fs) for f in freqs), [])))
    u = band_limited(rng, n, 0.02, 1.0, fs) if oversampled else rng.standard_normal(n)
    y = lfilter([0.0, 1.0, 0.5], a, u)
    y = y + np.std(y) * 10 ** (-30 / 20) * lfilter([1.0, -0.5], [1.0], rng.standard_normal(n))
    return u / np.std(u), y / np.std(y), a.size - 1


def _kappa(phi):
    """Condition number of Φ with its columns scaled to unit norm."""
    return float(np.linalg.cond(phi / np.linalg.norm(phi, axis=0)))


def _reference(u, y, e, na, nb, nc, d):
    phi, t, k0 = regression_matrix(u, y, e, na, nb, nc, d)
    return np.linalg.lstsq(phi, t, rcond=None)[0], phi, k0


def _rel(x, ref):
    return float(np.linalg.norm(x - ref) / np.linalg.norm(ref))


@pytest.mark.parametrize("oversampled", [False, True])
def test_the_solve_is_lstsq_to_the_conditioning(rng, oversampled):
    u, y, na = _record(rng, oversampled)
    nb, nc, d = 2, 2, 1
    e = rng.standard_normal(u.size)  # any c-regressors: the solve does not care
    ref, phi, k0 = _reference(u, y, e, na, nb, nc, d)
    theta = gram_lstsq(np.vstack([y, u, e]), pk.els_layout(na, nb, nc, d), k0)
    kappa = _kappa(phi)
    if oversampled:  # above the threshold: Φ formed and solved by lstsq, ε κ
        assert kappa > _COND_GRAM
        assert _rel(theta, ref) <= 10 * EPS * kappa
    else:  # through ΦᵀΦ: ε κ², with n for the sums' rounding
        assert kappa < 1e3
        assert _rel(theta, ref) <= theta.size * EPS * kappa**2


def test_the_solve_through_the_gram_matrix_near_its_threshold(rng):
    """A 4th-order loop (0.4 and 1 Hz) sampled at 300 Hz, driven by noise band-limited to
    0.02–2 Hz: κ ≈ 1e4, still through ΦᵀΦ, whose ε κ² bound is then ~1e-7."""
    n, fs = 6000, 300.0
    a = np.real(np.poly(sum((resonance_poles(f, 0.3, fs) for f in (0.4, 1.0)), [])))
    u = band_limited(rng, n, 0.02, 2.0, fs)
    y = lfilter([0.0, 1.0, 0.5], a, u)
    y = (y + 0.03 * np.std(y) * rng.standard_normal(n)) / np.std(y)
    e = rng.standard_normal(n)
    ref, phi, k0 = _reference(u, y, e, 4, 2, 2, 1)
    theta = gram_lstsq(np.vstack([y, u, e]), pk.els_layout(4, 2, 2, 1), k0)
    kappa = _kappa(phi)
    assert 1e3 < kappa < _COND_GRAM
    assert _rel(theta, ref) <= theta.size * EPS * kappa**2


def test_arx_solve_with_no_c_regressors(rng):
    u, y, na = _record(rng, oversampled=False)
    ref, phi, k0 = _reference(u, y, None, na, 3, 0, 0)
    theta = gram_lstsq(np.vstack([y, u]), pk.els_layout(na, 3, 0, 0), k0)
    assert _rel(theta, ref) <= theta.size * EPS * _kappa(phi) ** 2


def test_a_wrong_solve_is_seen(rng):
    """The comparison can fail: one sample less in the regression is far outside it."""
    u, y, na = _record(rng, oversampled=False)
    ref, phi, k0 = _reference(u, y, None, na, 2, 0, 1)
    theta = gram_lstsq(np.vstack([y, u]), pk.els_layout(na, 2, 0, 1), k0 + 1)
    assert _rel(theta, ref) > 1e3 * theta.size * EPS * _kappa(phi) ** 2


def _els_lstsq(u, y, na, nb, nc, d, iters):
    """``iters`` ELS iterations written with ``lstsq`` of the formed regressors."""
    theta = np.zeros(na + nb + 1 + nc)
    theta[: na + nb + 1] = _reference(u, y, None, na, nb, 0, d)[0]
    for _ in range(iters):
        e = prediction_errors(theta, u, y, na, nb, nc, d)
        theta = _reference(u, y, e, na, nb, nc, d)[0]
        theta[na + nb + 1 :] = stabilise(theta[na + nb + 1 :])
    return theta


@pytest.mark.parametrize("oversampled", [False, True])
def test_els_iterations_follow_the_lstsq_ones(rng, oversampled):
    u, y, na = _record(rng, oversampled)
    nb, nc, d = 2, 1, 1
    ref = _els_lstsq(u, y, na, nb, nc, d, 5)
    theta = els_theta(u, y, na, nb, nc, d, max_iter=5, tol=0.0)
    # each iteration's regressors carry the previous one's error (the map is a
    # contraction near the fixed point): 1e-6 is far above ε κ² per solve (κ ≤ 1e5
    # through ΦᵀΦ) and far below a wrong iteration (one less moves θ by > 1e-3)
    assert _rel(theta, ref) <= 1e-6
    assert _rel(_els_lstsq(u, y, na, nb, nc, d, 4), ref) > 1e-3


@pytest.mark.parametrize("orders", [(4, 3, 2, 0), (2, 1, 1, 1), (1, 0, 3, 0), (3, 2, 1, 4)])
def test_one_pass_filters_are_the_errors_and_signals_bit_for_bit(rng, orders):
    """The prediction-error fit's one-pass kernel against the two it fuses."""
    na, nb, nc, d = orders
    u, y, _ = _record(rng, oversampled=False)
    theta = np.concatenate([0.3 * rng.standard_normal(na + nb + 1),
                            np.real(np.poly(0.8 * np.exp(2j * np.pi * rng.random(nc))))[1:]])
    eps = pk.armax_errors(theta, u, y, na, nb, nc, d)
    ref = pk.armax_signals(theta, u, y, eps, na, nb, nc)
    assert np.array_equal(pk.armax_filtered(theta, u, y, na, nb, nc, d), ref)
