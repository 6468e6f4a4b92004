"""Drive-file iteration: run logs, default gain, refused updates, wrong models, FRF updates."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from ehss.compensation import (
    IterationState,
    UpdateOptions,
    design_inverse,
    lag_samples,
    run_record,
    update_drive,
)
from ehss.compensation.iteration import MAX_HALVINGS
from ehss.errors import ParameterError
from ehss.experiments.refinement import refine
from ehss.identification.model import ArmaxModel
from ehss.signals import band_limited_random

FS = 1000.0
BAND = (0.0, 60.0)


@pytest.fixture
def model():
    a = np.real(np.poly([0.95, 0.85 + 0.2j, 0.85 - 0.2j]))
    b = 0.01 * np.poly([0.4])
    return ArmaxModel(a=a, b=b, c=[1.0], delay=1, dt=1 / FS, band_hz=BAND)


@pytest.fixture
def reference():
    # 0.5-40 Hz random, 8 s, at rest at both ends (the generator zeroes two end samples).
    return np.asarray(band_limited_random(band_hz=(0.5, 40.0), duration_s=8.0, fs=FS,
                                          seed=11, rms=1.0).values)


def _phase_shifted(model, gain, phase_deg):
    """Plant ``gain·e^{-jφ}·G`` at every frequency (an FFT over the record, at rest)."""
    rot = gain * np.exp(-1j * np.radians(phase_deg))

    def plant(u):
        y = model.simulate(u)
        return np.fft.irfft(np.fft.rfft(y) * rot, y.size)

    return plant


def test_lag_of_a_delayed_copy(rng):
    r = np.convolve(rng.standard_normal(4000), np.ones(5) / 5, mode="same")
    y = np.r_[np.zeros(3), r[:-3]]
    # Integer delay of a smooth broadband signal: a symmetric correlation peak, so the
    # parabola adds nothing but rounding and the edge effect of 3 samples in 4000.
    assert lag_samples(r, y) == pytest.approx(3.0, abs=0.05)
    assert lag_samples(y, r) == pytest.approx(-3.0, abs=0.05)


def test_run_record_figures():
    t = np.arange(1000) / FS
    r = np.sin(2 * np.pi * 5 * t)
    y = 0.9 * r
    rec = run_record(r, 2.0 * r, y)
    assert rec.rms_error == pytest.approx(0.1 * np.sqrt(0.5), rel=1e-12)
    assert rec.peak_error == pytest.approx(0.1, rel=1e-6)
    assert rec.nrmse_percent == pytest.approx(10.0, rel=1e-12)
    assert rec.drive_rms_gain == pytest.approx(2.0) and rec.drive_peak_gain == pytest.approx(2.0)
    assert set(rec.to_dict()) >= {"rms_error", "lag_samples", "nrmse_percent"}


def test_growing_error_refuses_the_update_and_halves_the_gain(model, reference):
    base = np.zeros_like(reference)
    corr = np.ones_like(reference)
    state = IterationState(base_drive=base, correction=corr, gain=1.0, base_rms_error=0.1)
    worse = reference + 0.2  # RMS error 0.2 > 0.1
    step = update_drive(reference, base + corr, worse, fs=FS, model=model, state=state)
    assert not step.accepted and not step.stopped
    assert step.gain == 0.5 and step.state.halvings == 1
    assert_allclose(step.drive, base + 0.5 * corr, rtol=0, atol=0)
    for k in range(2, MAX_HALVINGS + 2):
        step = update_drive(reference, step.drive, worse, fs=FS, model=model, state=step.state)
        if k <= MAX_HALVINGS:
            assert step.gain == 0.5**k and not step.stopped
    assert step.stopped and "stopped" in step.message
    assert_allclose(step.drive, base, rtol=0, atol=0)  # the best drive is handed back


@pytest.mark.parametrize("fixed_gain", [None, 1.0])
def test_wrong_model_gain_2x_phase_30_deg_converges_or_stops(model, reference, fixed_gain):
    # The plant is 2·e^{-j30°} times the model. With L = 1 the error would grow by
    # |1 - 2e^{-j30°}| = 1.24 per update; the default gain is chosen from the first run
    # (L = 1/2: |1 - e^{-j30°}| = 0.52), a fixed L = 1 is refused once and halved.
    res = refine(_phase_shifted(model, 2.0, 30.0), reference, model=model,
                 options=UpdateOptions(gain=fixed_gain), iterations=5, max_gain=None)
    err = res.rms_error
    # accepted[k]: run k improved on the run its drive was built from (run 0: no judge)
    kept = [e for e, ok in zip(err, res.accepted, strict=False) if ok]
    assert np.all(np.diff(kept) < 0)  # accepted runs only ever improve
    assert np.min(err) < 0.2 * err[0]  # and the iteration makes progress
    assert np.max(err) <= 1.25 * err[0]  # a refused run costs at most one 1.24× step
    if fixed_gain is None:
        assert res.gains[0] == 0.5 and all(res.accepted)
    else:
        assert res.accepted[:2] == [True, False] and res.gains[1] == 0.5


def test_model_too_wrong_for_any_gain_stops(model, reference):
    # 120° of phase error: |1 - L e^{-j120°}| > 1 for every L > 0. The default gain
    # refuses to start; a fixed gain is refused and halved until the iteration stops.
    plant = _phase_shifted(model, 1.0, 120.0)
    with pytest.raises(ParameterError, match="too large for a stable update"):
        refine(plant, reference, model=model, iterations=2, max_gain=None)
    res = refine(plant, reference, model=model, iterations=2, max_gain=None,
                 stop_without_gain=True)  # as an experiment does: stop, keep the drive
    assert res.stopped and "too large" in res.message and len(res.drives) == 1
    res = refine(plant, reference, model=model, options=UpdateOptions(gain=1.0),
                 iterations=10, max_gain=None)
    assert res.stopped
    assert int(np.argmin(res.rms_error)) == 0  # nothing beat the first run
    assert res.drive is res.drives[0]
    assert len(res.drives) == 1 + 1 + MAX_HALVINGS  # first run, update, three halvings


def test_frf_iteration_converges_without_a_model(model, reference):
    # The industry's non-parametric iteration: start from the reference itself, invert
    # the measured H1 of each run. Plant: 1.3× the model with other poles.
    a_true = np.real(np.poly([0.93, 0.8 + 0.25j, 0.8 - 0.25j]))
    true = ArmaxModel(a=a_true, b=0.02 * np.poly([0.4]), c=[1.0], delay=2, dt=1 / FS)
    res = refine(lambda u: true.simulate(u), reference, model=model,
                 options=UpdateOptions(method="frf"), iterations=3, first_drive=reference)
    nrmse = [rec.nrmse_percent for rec in res.records]
    assert np.all(np.diff(res.rms_error) < 0)
    # H1 with 1 Hz resolution on an 8 s record, interpolated onto the record's grid: each
    # update removes the error but for the interpolation between bins (~1 % of it).
    assert nrmse[0] > 30.0 and nrmse[-1] < 1.0


def test_update_options_checked(model, reference):
    u = reference.copy()
    with pytest.raises(ParameterError, match="method"):
        update_drive(reference, u, u, fs=FS, model=model,
                     options=UpdateOptions(method="ilc"))
    with pytest.raises(ParameterError, match="gain"):
        update_drive(reference, u, u, fs=FS, model=model, options=UpdateOptions(gain=2.5))
    with pytest.raises(ParameterError, match="same length"):
        update_drive(reference, u[:-1], u, fs=FS, model=model)
    with pytest.raises(TypeError, match="IterationState"):
        update_drive(reference, u, u, fs=FS, model=model, state={"gain": 1})
    nob = ArmaxModel(a=model.a, b=model.b, c=[1.0], delay=1, dt=1 / FS)
    with pytest.raises(ParameterError, match="needs a band"):
        update_drive(reference, u, 0.9 * u, fs=FS, model=nob)
    inv = design_inverse(model)
    step = update_drive(reference, u, 0.9 * u, fs=FS,
                        options=UpdateOptions(band_hz=BAND, gain=1.0), inverse=inv)
    # u + F (r - 0.9 G u) with G F = 1 in band (r = G u exactly only in band): the
    # update adds F·0.1·r.
    assert step.accepted and step.gain == 1.0
