"""Output-error refits: a given start, a record cut out of a running test (``first``),
and records fitted together (``records``), against known systems and an independent
least-squares fit of the same loss."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares
from scipy.signal import lfilter

from ehss.errors import DataError, ParameterError
from ehss.identification.model import ArmaxModel
from ehss.identification.pem import oe_pem

from .systems import DT_S, band_limited, system


def _truth(order: int = 4) -> ArmaxModel:
    a, b, _ = system(order)
    return ArmaxModel(a=a, b=b, c=a, delay=1, dt=DT_S)


def _theta(m: ArmaxModel) -> np.ndarray:
    return np.r_[m.a[1:], m.b]


def _running_record(rng, truth: ArmaxModel, n: int, cut: int, **band):
    """A record cut out of a longer one at sample ``cut``: the output is not at rest
    at its first sample."""
    u = band_limited(rng, n + cut, **band)
    y = truth.simulate(u)
    return u[cut:], y[cut:]


def test_first_leaves_the_start_of_a_running_record_out(rng):
    truth = _truth()
    u, y = _running_record(rng, truth, 3000, 5000)
    start = _theta(truth) * np.r_[np.ones(4), 1.02 * np.ones(truth.b.size)]
    # the slowest pole of the 4th-order system (10 Hz, ζ = 0.2 at 1 kHz) decays by e^-1
    # in 1 / (2π 10 · 0.2 / 1000) = 80 samples: from rest, the model's start-up is
    # e^-19 ≈ 6e-9 of the record's state after 1500
    cut = oe_pem(u, y, nf=4, nb=truth.b.size - 1, theta0=start, first=1500, dt=DT_S,
                 tol=1e-14)
    assert cut.meta["start"] == "given"
    # noise-free: the exact system over the drive's band (2-100 Hz), to 1e-7 (the
    # coefficients of poles this near the unit circle are a thousand times as
    # sensitive as the response)
    f = np.linspace(2.0, 100.0, 50)
    miss = np.abs(cut.frequency_response(f) / truth.frequency_response(f) - 1.0)
    assert np.max(miss) < 1e-7
    # counted from the first sample, the start-up from rest that the record does not
    # have biases the fit
    whole = oe_pem(u, y, nf=4, nb=truth.b.size - 1, theta0=start, dt=DT_S, tol=1e-14)
    whole_miss = np.abs(whole.frequency_response(f) / truth.frequency_response(f) - 1.0)
    assert np.max(whole_miss) > 1e-3


def _joint_errors(u, y, first, records, nf):
    """The errors of the joint loss, computed on their own (lfilter simulations): those
    of ``u, y`` from ``first`` on, then each record's times its weight."""

    def errors(theta):
        f = np.r_[1.0, theta[:nf]]
        b = np.r_[0.0, theta[nf:]]
        out = [(y - lfilter(b, f, u))[first:]]
        out += [w * (yr - lfilter(b, f, ur))[nf:] for ur, yr, w in records]
        return np.concatenate(out)

    return errors


def test_records_fitted_together_match_an_independent_fit(rng):
    # a band-limited record (2-60 Hz of a system with a resonance at 45 Hz) and a
    # prior model's response to white noise, weighted 0.3
    truth = _truth()
    nb = truth.b.size - 1
    u, y = _running_record(rng, truth, 2000, 3000, f_hi=60.0)
    y = y + 0.01 * np.std(y) * rng.standard_normal(y.size)
    prior = ArmaxModel(a=truth.a, b=1.05 * truth.b, c=truth.a, delay=1, dt=DT_S)
    noise = rng.standard_normal(800)
    records = [(noise, prior.simulate(noise), 0.3)]
    start = _theta(prior)
    fit = oe_pem(u, y, nf=4, nb=nb, theta0=start, first=600, records=records, dt=DT_S,
                 max_nfev=500, tol=1e-14)
    errors = _joint_errors(u, y, 600, records, 4)
    cost = float(np.sum(errors(_theta(fit)) ** 2))
    # scipy's own Levenberg–Marquardt on those errors (finite differences) from the
    # same start ends no lower, and from the fit moves it by nothing that matters: the
    # fit is the minimum of that loss
    ref = least_squares(errors, start, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15,
                        max_nfev=20000).x
    assert cost <= float(np.sum(errors(ref) ** 2)) * (1.0 + 1e-9)
    again = least_squares(errors, _theta(fit), method="lm", xtol=1e-15, ftol=1e-15,
                          gtol=1e-15, max_nfev=20000).x
    assert float(np.sum(errors(again) ** 2)) >= cost * (1.0 - 1e-9)
    # while the loss counted from the first sample, without the prior, is another one
    alone = oe_pem(u, y, nf=4, nb=nb, theta0=start, first=600, dt=DT_S)
    assert float(np.sum(errors(_theta(alone)) ** 2)) > cost * (1.0 + 1e-3)


def test_a_prior_record_rules_where_the_data_say_nothing(rng):
    # a drive of 2-20 Hz with 1 % noise says little of the 45-Hz resonance: alone, the
    # fit spends it on the noise (15 % off there); a prior record (the true system's
    # response to white noise) pins it down and leaves the band as the data say
    truth = _truth()
    nb = truth.b.size - 1
    u, y = _running_record(rng, truth, 2000, 3000, f_hi=20.0)
    y = y + 0.01 * np.std(y) * rng.standard_normal(y.size)
    start = _theta(truth) * np.r_[np.ones(4), 1.1 * np.ones(nb + 1)]
    noise = rng.standard_normal(600)
    alone = oe_pem(u, y, nf=4, nb=nb, theta0=start, first=600, dt=DT_S)
    with_prior = oe_pem(u, y, nf=4, nb=nb, theta0=start, first=600, dt=DT_S,
                        records=[(noise, truth.simulate(noise), 1.0)])

    def miss(m, f):
        return np.abs(m.frequency_response(f) / truth.frequency_response(f) - 1.0)

    outside = np.array([45.0, 100.0])
    assert np.max(miss(with_prior, outside)) < 0.05
    assert np.all(miss(with_prior, outside) < miss(alone, outside) / 5.0)
    # in the band both within 0.3 % (1 % noise over 1400 samples of a 18-Hz band)
    inside = np.linspace(3.0, 18.0, 20)
    assert np.max(miss(with_prior, inside)) < 3e-3 and np.max(miss(alone, inside)) < 3e-3


@pytest.mark.parametrize(("kw", "error", "match"), [
    ({"records": [(np.ones(10), np.ones(10))]}, ParameterError, r"records\[0\] must be"),
    ({"records": [(np.ones(100), np.ones(100), 0.0)]}, ParameterError, "weight=0.0"),
    ({"records": [(np.ones(100), np.ones(100), np.nan)]}, ParameterError, "weight=nan"),
    ({"first": 196}, DataError, "first=196: 4 samples left"),
    ({"first": -1}, ParameterError, "first=-1"),
    ({"theta0": [0.1, 0.2]}, ParameterError, "theta0 has shape"),
])
def test_bad_refit_input(rng, kw, error, match):
    u = rng.standard_normal(200)
    with pytest.raises(error, match=match):
        oe_pem(u, lfilter([0, 0.5], [1, -0.5], u), nf=2, nb=1, **kw)
