"""Identification and acceptance of one loop record, on systems known exactly."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal as sps

from ehss.experiments.loop_identification import (
    ACCEPTANCE,
    identify_and_check,
    loop_record,
    simplest_passing,
)

FS = 1000.0
A = np.array([1.0, -1.5, 0.7])  # poles at radius 0.84
B = np.array([0.1, 0.05])  # b0, b1 after one sample of delay
PERIOD = 1000  # 1 Hz resolution
OFFSETS = (2.0, -3.0)  # operating point (u0, y0)


def _multisine(rng, n_periods):
    """Zero-mean periodic excitation, 2–100 Hz, with random phases."""
    k = np.arange(2, 101)
    t = np.arange(PERIOD) / FS
    one = np.sum(np.cos(2 * np.pi * np.outer(k, t) + rng.uniform(0, 2 * np.pi, (k.size, 1))),
                 axis=0)
    one -= one.mean()
    return np.tile(one / np.std(one), n_periods)


def _record(rng, num, den, n_periods=20):
    """The response from rest, so that an estimator starting from zero regressors sees
    consistent equations from the first sample; about the operating point OFFSETS."""
    u = _multisine(rng, n_periods)
    y = sps.lfilter(num, den, u)
    return u + OFFSETS[0], y + OFFSETS[1]


def _response(num, den, f_hz):
    return sps.freqz(num, den, worN=f_hz, fs=FS)[1]


def test_record_is_taken_about_its_operating_point_and_split(rng):
    u_raw, y_raw = _record(rng, np.r_[0.0, B], A)
    rec = loop_record(u_raw, y_raw, fs=FS, band_hz=(2.0, 100.0), holdout=0.3)
    assert rec.n_ident == 14_000
    # Whole periods of a zero-mean input: its mean is the operating point, to rounding;
    # the output's differs from it by the start-up transient's share, O(1/n) (3e-5 here).
    assert rec.input_mean == pytest.approx(OFFSETS[0], abs=1e-12)
    assert rec.output_mean == pytest.approx(OFFSETS[1], abs=1e-3)
    np.testing.assert_allclose(rec.u + rec.input_mean, u_raw, rtol=0, atol=1e-12)
    # Prepared as ehss identify prepares it: each part about its own mean, no decimation.
    p = rec.prepared
    assert p.decimation == 1 and p.holdout == 0.3 and p.band_hz == (2.0, 100.0)
    assert p.u.size == 14_000 and p.u_val.size == 6_000
    np.testing.assert_allclose(p.u, u_raw[:14_000] - np.mean(u_raw[:14_000]), atol=1e-12)
    np.testing.assert_allclose(p.y_val, y_raw[14_000:] - np.mean(y_raw[14_000:]), atol=1e-12)


def test_a_known_system_is_identified_and_passes(rng):
    u_raw, y_raw = _record(rng, np.r_[0.0, B], A)
    rec = loop_record(u_raw, y_raw, fs=FS, band_hz=(2.0, 100.0), holdout=0.3)
    check = identify_and_check(rec, (2, 1, 0, 1), forgetting=1.0, p0=1e6)
    assert check.label == "RELS (2,1,0,1)"
    # Noise-free, of the model's structure and from rest: what separates the estimate
    # from the truth is the start-up transient's share of the output mean, removed with
    # the operating point and seen as a constant disturbance (O(1/n), 1e-7 here), and
    # P(0) = 1e6·I (a relative pull of order 1e-6/n): 1e-4 bounds both.
    f = np.linspace(2.0, 100.0, 50)
    np.testing.assert_allclose(check.model.frequency_response(f),
                               _response(np.r_[0.0, B], A, f), rtol=1e-4)
    assert check.passes and check.verdict.failed == ()
    assert check.fit_pct > 99.9 and check.raw_fit_pct > 99.9
    # The simulated output is returned about the operating point, like the measurement.
    np.testing.assert_allclose(check.simulated[rec.n_ident:], y_raw[rec.n_ident:],
                               atol=1e-3 * np.std(y_raw))


def test_too_simple_a_model_fails_and_the_search_finds_the_true_order(rng):
    u_raw, y_raw = _record(rng, np.r_[0.0, B], A)
    rec = loop_record(u_raw, y_raw, fs=FS, band_hz=(2.0, 100.0), holdout=0.3)
    low = identify_and_check(rec, (1, 0, 0, 1), forgetting=1.0, p0=1e6)
    # A first-order model cannot follow the 0.84-radius resonance: far outside 1 dB / 5°.
    assert not low.passes
    assert low.fit_pct < ACCEPTANCE.min_fit_pct
    assert any(f.startswith("fit ") for f in low.verdict.failed)
    assert any(f.startswith("magnitude error") for f in low.verdict.failed)
    found = simplest_passing(rec, (1, 0, 0, 1), max_order=4, forgetting=1.0, p0=1e6)
    assert found is not None and found.passes
    assert found.model.na == 2  # the simplest that passes is the true order


def test_identified_behind_known_factors_the_complete_model_is_composed(rng):
    # A known high-pass F = (1 − q⁻¹)/(1 − 0.99 q⁻¹) in front of the unknown part
    # (np.convolve, not np.polymul, which would drop the delay's leading zero).
    f_num, f_den = np.array([1.0, -1.0]), np.array([1.0, -0.99])
    num, den = np.convolve(f_num, np.r_[0.0, B]), np.convolve(f_den, A)
    u_raw, y_raw = _record(rng, num, den)
    rec = loop_record(u_raw, y_raw, fs=FS, band_hz=(2.0, 100.0), holdout=0.3)
    check = identify_and_check(rec, (2, 1, 0, 1), forgetting=1.0, p0=1e6,
                               known=(f_num, f_den))
    assert check.label.endswith("behind the known generator and accelerometer coupling")
    assert check.model.na == 3  # the complete model carries F's pole and zero
    assert check.model.nb == 2
    f = np.linspace(2.0, 100.0, 50)
    # As above (the high-pass has no DC gain, so the constant left by the mean removal
    # weighs more: 7e-6 here); 1e-4 bounds it.
    np.testing.assert_allclose(check.model.frequency_response(f), _response(num, den, f),
                               rtol=1e-4)
    assert check.passes
