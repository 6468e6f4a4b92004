"""Fit figures, frequency-response error and residual tests against analytic answers."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
import scipy.signal
import scipy.stats

from ehss.errors import DataError, ParameterError
from ehss.frequency import FrequencyResponse
from ehss.identification.model import ArmaxModel
from ehss.io import to_jsonable
from ehss.validation import (
    DIVERGED_FIT_PCT,
    band_fit,
    fit_text,
    free_run,
    frf_error,
    ljung_box,
    nrmse_fit,
    prediction_fit,
    residual_tests,
    simulation_fit,
    validate,
)

FS = 1000.0


@pytest.fixture
def true_model():
    # A y = q^-1 B u + C e with a resonance at ~40 Hz: stable, stably invertible C.
    r, th = 0.95, 2 * np.pi * 40 / FS
    a = [1.0, -2 * r * np.cos(th), r * r]
    return ArmaxModel(a=a, b=[0.02, 0.015], c=[1.0, 0.5], delay=1, dt=1 / FS)


def _armax_data(model, rng, n=20_000, sigma_e=0.01):
    u = rng.standard_normal(n)
    e = sigma_e * rng.standard_normal(n)
    y = model.simulate(u) + scipy.signal.lfilter(model.c, model.a, e)
    return u, y, e


# ------------------------------------------------------------------------------ nrmse_fit


def test_nrmse_fit_analytic():
    y = np.array([1.0, -1.0, 1.0, -1.0])
    assert nrmse_fit(y, y) == 100.0
    assert nrmse_fit(y, np.zeros(4)) == 0.0  # the mean predictor
    assert nrmse_fit(y, 0.5 * y) == pytest.approx(50.0, abs=1e-12)
    assert nrmse_fit(y, -y) == pytest.approx(-100.0, abs=1e-12)
    assert nrmse_fit(y, np.array([np.inf, 0, 0, 0])) == -math.inf
    with pytest.raises(DataError, match="constant"):
        nrmse_fit(np.ones(4), np.zeros(4))
    with pytest.raises(DataError, match="same length"):
        nrmse_fit(y, y[:3])


# ------------------------------------------------------------------------------ frf_error


def test_frf_error_exact_offsets(true_model):
    f = np.linspace(1.0, 200.0, 200)
    g = true_model.frequency_response(f)
    coh = np.ones_like(f)
    coh[::4] = 0.5  # a quarter of the points are unreliable
    # The "measurement" is the model times 1 dB and -10°: the error is exactly that.
    h = g * 10 ** (-1 / 20) * np.exp(1j * np.radians(10.0))
    frf = FrequencyResponse(freq_hz=f, response=h, coherence=coh, n_averages=10, nperseg=1000,
                            fs=FS)
    err = frf_error(true_model, frf, band_hz=(10.0, 100.0))
    n_band = np.sum((f >= 10) & (f <= 100))
    assert err.n_points == n_band - np.sum((f >= 10) & (f <= 100) & (coh < 0.9))
    assert err.compared_hz == (10.0, 100.0)
    # the span of the points really compared: 9 Hz is an unreliable point, so it starts at 10
    assert frf_error(true_model, frf, band_hz=(9.0, 100.0)).compared_hz == (10.0, 100.0)
    assert coh[f == 9.0] < 0.9
    # float64 rounding of the offsets only
    assert err.max_magnitude_db == pytest.approx(1.0, abs=1e-9)
    assert err.rms_magnitude_db == pytest.approx(1.0, abs=1e-9)
    assert err.weighted_rms_magnitude_db == pytest.approx(1.0, abs=1e-9)
    assert err.max_phase_deg == pytest.approx(10.0, abs=1e-9)
    assert err.rms_phase_deg == pytest.approx(10.0, abs=1e-9)
    assert json.dumps(err.summary())


def test_frf_error_standard_errors_and_unexcited_points(true_model):
    # coherence 0.9 and 8 averages: eps = sqrt(0.1 / (0.9 * 16)) = 0.08333 relative, i.e.
    # 20/ln(10) * eps = 0.7238 dB and 4.775 deg (Bendat & Piersol 9.90, 9.92)
    f = np.array([10.0, 20.0, 30.0])
    g = true_model.frequency_response(f)
    frf = FrequencyResponse(freq_hz=f, response=g, coherence=np.full(3, 0.9), n_averages=8,
                            nperseg=100, fs=FS, input_power=np.array([1.0, 1e-4, 0.5]))
    err = frf_error(true_model, frf, band_hz=(0.0, 100.0))
    eps = math.sqrt(0.1 / (0.9 * 16))
    # the 20 Hz point had 40 dB less input than the strongest: not excited, not compared
    assert err.n_points == 2 and err.freq_hz.tolist() == [10.0, 30.0]
    np.testing.assert_allclose(err.sigma_magnitude_db, 20 / math.log(10) * eps, rtol=1e-12)
    np.testing.assert_allclose(err.sigma_phase_deg, math.degrees(eps), rtol=1e-12)
    assert err.beyond_uncertainty(2.0) == (0.0, 0.0)


def test_the_point_furthest_beyond_the_estimate_is_found(true_model):
    # the estimate off the model by 2 dB at 10 Hz, and by 12 deg at 30 Hz; both points
    # of coherence 0.9 over 8 averages (standard errors 0.7238 dB and 4.775 deg, above).
    # Less two of them, 0.553 dB against a bound of 1 dB and 2.45 deg against 5 deg: the
    # magnitude's share is the larger (0.553 against 0.49), so 10 Hz, and more so with
    # a bound of 0.5 dB (1.106); with a phase bound of 2 deg (1.225 against 0.553), 30 Hz
    f = np.array([10.0, 20.0, 30.0])
    g = true_model.frequency_response(f)
    off = np.array([10 ** (2.0 / 20.0), 1.0, np.exp(1j * np.radians(12.0))])
    frf = FrequencyResponse(freq_hz=f, response=g * off, coherence=np.full(3, 0.9),
                            n_averages=8, nperseg=100, fs=FS)
    err = frf_error(true_model, frf, band_hz=(0.0, 100.0))
    assert err.worst_beyond_uncertainty(2.0, 1.0, 5.0) == 10.0
    assert err.worst_beyond_uncertainty(2.0, 0.5, 5.0) == 10.0
    assert err.worst_beyond_uncertainty(2.0, 1.0, 2.0) == 30.0
    # over the points above 10 Hz only: none of the magnitude's miss, the phase's
    eps_deg = math.degrees(math.sqrt(0.1 / (0.9 * 16)))
    mag, ph = err.beyond_uncertainty(2.0, err.freq_hz > 10.0)
    assert mag == 0.0 and ph == pytest.approx(12.0 - 2 * eps_deg, abs=1e-9)
    assert all(math.isnan(x) for x in err.beyond_uncertainty(2.0, err.freq_hz > 100.0))
    empty = frf_error(true_model, dataclasses.replace(frf, coherence=np.zeros(3)),
                      band_hz=(0.0, 100.0))
    assert math.isnan(empty.worst_beyond_uncertainty(2.0, 1.0, 5.0))


def test_frf_error_phase_is_wrapped(true_model):
    f = np.array([5.0, 10.0])
    g = true_model.frequency_response(f)
    # 355° off is 5° off.
    frf = FrequencyResponse(freq_hz=f, response=g * np.exp(1j * np.radians(355.0)),
                            coherence=np.ones(2), n_averages=1, nperseg=8, fs=FS)
    assert frf_error(true_model, frf, band_hz=(0, 20)).max_phase_deg == pytest.approx(5.0)


def test_frf_error_no_points(true_model):
    frf = FrequencyResponse(freq_hz=np.array([1.0, 2.0]), response=np.ones(2, complex),
                            coherence=np.array([0.1, 0.2]), n_averages=1, nperseg=8, fs=FS)
    err = frf_error(true_model, frf, band_hz=(0, 10))
    assert err.n_points == 0 and math.isnan(err.max_magnitude_db)
    assert all(math.isnan(x) for x in err.compared_hz)
    with pytest.raises(ParameterError, match="min_coherence"):
        frf_error(true_model, frf, band_hz=(0, 10), min_coherence=2)
    with pytest.raises(ParameterError, match="lo < hi"):
        frf_error(true_model, frf, band_hz=(10, 0))


# --------------------------------------------------------------------- simulation/prediction


def test_simulation_fit_of_true_model_noise_free(true_model, rng):
    u = rng.standard_normal(5000)
    y = true_model.simulate(u)
    assert simulation_fit(true_model, u, y) == pytest.approx(100.0, abs=1e-10)
    assert simulation_fit(true_model, u, y, start=4000) == pytest.approx(100.0, abs=1e-10)


def test_prediction_fit_matches_innovation(true_model, rng):
    u, y, e = _armax_data(true_model, rng)
    # The one-step predictor of the true model leaves exactly the innovation (after the
    # transient of 1/C, |0.5|^k, long gone by sample 100).
    fit = prediction_fit(true_model, u, y, 1, start=100)
    expected = 100 * (1 - np.linalg.norm(e[100:]) / np.linalg.norm(y[100:] - y[100:].mean()))
    assert fit == pytest.approx(expected, abs=1e-9)
    # Predicting further ahead is never better here.
    assert prediction_fit(true_model, u, y, 5, start=100) < fit


# ------------------------------------------------------------------------- residual tests


def test_ljung_box_by_hand():
    x = np.array([0.3, -1.2, 0.8, 0.1, -0.5, 1.1, -0.9, 0.4, 0.0, -0.2])
    m = 3
    n = x.size
    d = x - x.mean()
    den = sum(v * v for v in d)
    q = 0.0
    for k in range(1, m + 1):
        rk = sum(d[t] * d[t - k] for t in range(k, n)) / den
        q += rk * rk / (n - k)
    q *= n * (n + 2)
    got_q, got_p = ljung_box(x, m)
    assert got_q == pytest.approx(q, rel=1e-12)  # same sums, different order
    assert got_p == pytest.approx(scipy.stats.chi2.sf(q, m), rel=1e-12)


def test_residuals_of_true_model_pass(true_model, rng):
    u, y, _ = _armax_data(true_model, rng)
    res = residual_tests(true_model, u, y, start=100)
    assert res.white and res.independent and res.passed
    assert res.ljung_box_p > 0.01
    assert res.autocorrelation[0] == 1.0
    assert res.lags.size == 26 and res.cross_lags.size == 51
    assert res.autocorrelation_bound == pytest.approx(
        scipy.stats.norm.ppf(0.995) / np.sqrt(res.n_samples))
    assert json.dumps(res.summary())


def test_coloured_residuals_fail(true_model, rng):
    u, y, _ = _armax_data(true_model, rng, sigma_e=0.05)
    # Ignoring C (an output-error guess with C = 1) leaves C-coloured residuals.
    wrong = ArmaxModel(a=true_model.a, b=true_model.b, c=[1.0], delay=1, dt=1 / FS)
    res = residual_tests(wrong, u, y, start=100)
    assert not res.white and res.ljung_box_p < 1e-10
    assert res.n_lags_outside >= 1


def test_input_correlated_residuals_fail(true_model, rng):
    u, y, _ = _armax_data(true_model, rng)
    wrong = ArmaxModel(a=true_model.a, b=0.8 * true_model.b, c=true_model.c, delay=1,
                       dt=1 / FS)
    res = residual_tests(wrong, u, y, start=100)
    assert not res.independent
    assert np.argmax(np.abs(res.cross_correlation)) - 25 >= 1  # past inputs


def test_residual_argument_checks(true_model, rng):
    u = rng.standard_normal(30)
    with pytest.raises(DataError, match="too few"):
        residual_tests(true_model, u, u, max_lag=25)
    with pytest.raises(ParameterError, match="alpha"):
        residual_tests(true_model, u, u, alpha=1.5)
    with pytest.raises(ParameterError, match="max_lag"):
        residual_tests(true_model, u, u, max_lag=0)


# ------------------------------------------------------------------------------- validate


def test_validate_bundle(true_model, rng):
    u, y, _ = _armax_data(true_model, rng, sigma_e=0.001)
    rep = validate(true_model, u, y, fs=FS, band_hz=(1, 100), holdout=0.3, horizons=(1, 10))
    assert rep.n_estimation == 14_000 and rep.n_validation == 6_000
    assert rep.stable and rep.max_pole_radius == pytest.approx(0.95)
    assert rep.simulation_fit_pct > 95 and set(rep.prediction_fit_pct) == {1, 10}
    assert rep.frf_error.n_points > 50
    # H1 of nearly noise-free data against the true response: leakage-limited, < 0.5 dB
    assert rep.frf_error.max_magnitude_db < 0.5
    assert rep.residuals.white
    summary = to_jsonable(rep.summary())
    assert json.loads(json.dumps(summary))["residuals"]["white"] is True
    text = rep.format()
    assert "simulation fit" in text and "Ljung-Box" in text


def test_validate_unstable_model_does_not_blow_up(true_model, rng):
    u, y, _ = _armax_data(true_model, rng, n=4000)
    unstable = ArmaxModel(a=[1.0, -1.5], b=[0.1], c=[1.0], delay=1, dt=1 / FS)
    rep = validate(unstable, u, y, fs=FS, band_hz=(1, 100))
    assert not rep.stable
    assert rep.simulation_fit_pct == -math.inf
    assert "diverges" in rep.format()
    assert to_jsonable(rep.summary())["simulation_fit_pct"] is None


def test_validate_short_holdout(true_model, rng):
    u = rng.standard_normal(100)
    with pytest.raises(DataError, match="validation part has 30 samples"):
        validate(true_model, u, u, fs=FS)
    with pytest.raises(ParameterError, match="holdout"):
        validate(true_model, u, u, fs=FS, holdout=1.5)


# ----------------------------------------------------------- initial state, divergence


def test_free_run_recovers_a_nonzero_initial_state(true_model, rng):
    # The record starts with the model in motion: y = free response + B/A u. From rest the
    # simulation misses the transient; the least-squares initial state finds it exactly
    # (noise-free, so to rounding: 1e-9 of a unit-scale signal).
    n = 3000
    u = rng.standard_normal(n)
    a, b = true_model.a, np.concatenate([[0.0], true_model.b])
    zi = scipy.signal.lfiltic(b, a, y=[3.0, -2.0], x=[0.5, 0.0])
    y = scipy.signal.lfilter(b, a, u, zi=zi)[0]
    assert simulation_fit(true_model, u, y, initial="estimate") == pytest.approx(100, abs=1e-9)
    assert simulation_fit(true_model, u, y, initial="zero") < 99.0
    assert_free = free_run(true_model, u, y, initial="estimate")
    np.testing.assert_allclose(assert_free, y, rtol=0, atol=1e-9)
    with pytest.raises(ParameterError, match="needs the measured output"):
        free_run(true_model, u, initial="estimate")
    with pytest.raises(ParameterError, match="initial"):
        free_run(true_model, u, y, initial="warm")


def test_unstable_model_is_simulated_from_rest_and_reported_as_diverging(rng):
    # A growing free response fitted to the data would hide the divergence: an unstable
    # model keeps the zero initial state.
    u = rng.standard_normal(2000)
    unstable = ArmaxModel(a=[1.0, -1.01], b=[0.1], c=[1.0], delay=1, dt=1 / FS)
    np.testing.assert_array_equal(free_run(unstable, u, u, initial="estimate"),
                                  unstable.simulate(u))
    fit = simulation_fit(unstable, u, u, initial="estimate")
    assert fit < DIVERGED_FIT_PCT
    assert fit_text(fit).startswith("diverges")
    assert fit_text(-99.0) == "-99.00 %" and fit_text(float("-inf")).startswith("diverges")


def test_diverging_fit_prints_no_long_number(rng):
    # pole radius 1.05 over 4000 samples grows to 1e84: the fit is a huge negative number,
    # which the report must show as a divergence, not as digits.
    u, y = rng.standard_normal(4000), rng.standard_normal(4000)
    unstable = ArmaxModel(a=[1.0, -1.05], b=[0.1], c=[1.0], delay=1, dt=1 / FS)
    rep = validate(unstable, u, y, fs=FS, holdout=None, band_hz=(1, 100))
    assert rep.diverged and rep.initial_state == "estimate"
    text = rep.format()
    assert "diverges" in text
    assert max(len(w) for w in text.split()) < 40
    summ = rep.summary()
    assert summ["diverged"] is True and summ["simulation_fit_pct"] is None


def test_band_fit_ignores_noise_above_the_band(true_model, rng):
    # White output noise as large as the signal: the raw fit is near 100(1 - 1/sqrt(2)),
    # but low-passing both at 1.5 x 20 Hz keeps the signal's low part (the model's
    # response is mostly below 50 Hz) and 3 % of the noise power.
    n = 20_000
    u = scipy.signal.lfilter(*scipy.signal.butter(4, 20, fs=FS), rng.standard_normal(n))
    clean = true_model.simulate(u)
    y = clean + np.std(clean) * rng.standard_normal(n)
    raw = nrmse_fit(y, clean)
    banded = band_fit(y, clean, fs=FS, band_hz=(0.0, 20.0))
    assert raw < 35.0 and banded > 75.0


def test_validate_on_a_separate_record(true_model, rng):
    u, y, _ = _armax_data(true_model, rng, n=5000, sigma_e=0.001)
    rep = validate(true_model, u, y, fs=FS, band_hz=(1, 100), holdout=None)
    assert rep.n_estimation == 0 and rep.n_validation == 5000
    assert rep.initial_state == "estimate"
    assert rep.simulation_fit_pct > 95 and rep.band_fit_pct > 95
    assert "separate record" in rep.format()
    rep0 = validate(true_model, u, y, fs=FS, holdout=None, initial="zero")
    assert rep0.initial_state == "zero" and "from rest" in rep0.format()
