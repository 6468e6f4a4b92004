"""A simulated test continued from its final state equals one run, bit for bit."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from ehss.errors import ParameterError
from ehss.params import preset
from ehss.signals import band_limited_random
from ehss.simulation import simulate


def _reference(loop: str, n: int, seed: int) -> np.ndarray:
    rms = {"position": 1e-3, "acceleration": 0.5, "force": 500.0}[loop]
    return band_limited_random(band_hz=(1.0, 40.0), rms=rms, duration_s=n / 1000.0, fs=1000.0,
                               seed=seed, fade_s=0.05).values[:n]


@pytest.mark.parametrize("loop", ["position", "acceleration", "force"])
def test_blocks_equal_one_run(loop):
    # delay_samples = 2: the delay line's index must carry over the block boundaries
    params = preset("default")
    params = dataclasses.replace(params, timing=dataclasses.replace(params.timing,
                                                                    delay_samples=2))
    r = _reference(loop, 1500, seed=3)
    whole = simulate(loop, r, params=params, seed=11)
    cuts = [0, 1, 7, 400, 401, 1000, 1500]  # blocks of 1 sample too
    state = None
    pieces = []
    for a, b in zip(cuts[:-1], cuts[1:], strict=True):
        run = simulate(loop, r[a:b], params=params, seed=11 if state is None else None,
                       initial_state=state)
        pieces.append(run)
        state = run.final_state
    for name, row in whole.signals.items():
        joined = np.concatenate([p.signals[name] for p in pieces])
        # bit for bit: the same operations in the same order
        np.testing.assert_array_equal(joined, row, err_msg=name)
    np.testing.assert_array_equal(state.memory, whole.final_state.memory)
    assert state.plant == whole.final_state.plant
    assert state.n_samples == r.size


def test_parameters_change_between_blocks_without_restarting_the_controller():
    # a heavier payload from the second block on: the controller's integral carries over,
    # so the drive is continuous at the boundary (a restarted PID would start at 0)
    params = preset("default")
    r = np.full(2000, 2e-3)
    first = simulate("position", r[:1000], params=params, seed=1)
    heavy = dataclasses.replace(params, load=dataclasses.replace(
        params.load, mass_kg=1.4 * params.load.mass_kg))
    second = simulate("position", r[1000:], params=heavy, initial_state=first.final_state)
    jump = abs(second.signals["drive_v"][0] - first.signals["drive_v"][-1])
    # at steady state the drive moves by far less than 1 % of its full scale per period
    assert jump < 0.01 * params.position.output_limit_v
    assert second.seed == first.seed


def test_a_state_continues_only_its_own_loop_and_timing():
    first = simulate("position", np.zeros(10), seed=1)
    with pytest.raises(ParameterError, match="loop"):
        simulate("force", np.zeros(10), initial_state=first.final_state)
    with pytest.raises(ParameterError, match="seed"):
        simulate("position", np.zeros(10), seed=2, initial_state=first.final_state)
    p = preset("default")
    other = dataclasses.replace(p, timing=dataclasses.replace(p.timing, delay_samples=3))
    with pytest.raises(ParameterError, match="delay"):
        simulate("position", np.zeros(10), params=other, initial_state=first.final_state)
