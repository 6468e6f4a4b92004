"""Compensation of the simulated rig's position loop with default settings."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from ehss.experiments.compensation_demo import LOOP_SETTINGS, random_reference
from ehss.experiments.refinement import refine
from ehss.identification import estimate
from ehss.params import preset
from ehss.signals import check_feasible
from ehss.simulation import simulate


@pytest.mark.slow
def test_position_loop_one_shot_cut_and_iterations_never_worse():
    params = preset("default")
    fs = float(params.timing.control_rate_hz)
    cfg = LOOP_SETTINGS["position"]
    # Identification on the paper's kind of test (0-100 Hz random), RML, the loop's
    # working band as the validated band.
    u_id = random_reference(16.0, fs, cfg["ident_hz"], cfg["ident_rms"], seed=0)
    y_id = simulate("position", u_id, params=params, seed=100).output
    o = cfg["orders"]
    model = estimate(u_id, y_id, method="rml", na=o["na"], nb=o["nb"], nc=o["nc"],
                     delay=o["delay"], dt=1 / fs)
    model = dataclasses.replace(model, band_hz=cfg["band_hz"])

    r = random_reference(16.0, fs, (0.5, 20.0), cfg["test_rms"], seed=1)
    check_feasible(r, "position", params, fs)  # inside the rig's limits
    without = np.std(simulate("position", r, params=params, seed=7).output - r)
    res = refine("position", r, model=model, params=params, iterations=2, seed=200)
    err = np.array([np.std(y - r) for y in res.outputs])
    assert without / err[0] >= 30.0  # one-shot cut (measured ~40×)
    assert np.all(err[1:] <= err[0])  # iterations never worse than the first run
