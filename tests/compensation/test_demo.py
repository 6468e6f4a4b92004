"""Compensation on the simulated rig (default tunings): the paper's working bands."""

from __future__ import annotations

import numpy as np
import pytest

from ehss.cli import main
from ehss.experiments.compensation_demo import demonstrate, plot_demo
from ehss.simulation import simulate


@pytest.fixture(scope="module")
def position_demo():
    return demonstrate("position", seed=0, duration_s=16.0, iterations=2)


@pytest.mark.slow
def test_position_loop_within_1db_5deg_and_10x(position_demo):
    d = position_demo
    assert d.judge_hz == (1.0, 20.0)
    assert d.with_.max_abs_db <= 1.0
    assert d.with_.max_abs_deg <= 5.0
    assert d.improvement["random"] >= 10.0
    # The uncompensated loop is far from it, so the test is not trivially met.
    assert d.without.max_abs_deg > 5.0


@pytest.mark.slow
def test_acceleration_loop_within_1db_5deg_and_10x():
    # Identified behind the known generator (eq 10) and accelerometer coupling on the
    # paper's 2-100 Hz random test; compensated as rest⁻¹ ∘ known⁻¹ (band 1-50 Hz).
    d = demonstrate("acceleration", seed=0, duration_s=16.0, iterations=2)
    assert d.judge_hz == (1.0, 50.0)
    assert d.with_.max_abs_db <= 1.0
    assert d.with_.max_abs_deg <= 5.0
    assert d.improvement["random"] >= 10.0
    assert d.without.max_abs_deg > 5.0
    # The model alone does it: the one-shot inverse already reduces the random error
    # ≥ 10× (measured ~10× over seeds 0-3 with tests inside the rig's limits), and the
    # drive-file iteration lowers it run after run until the sensor-noise floor: the
    # loop's output noise with a zero reference (~0.019 m/s² RMS); within 20 % of that
    # floor the next run may be no better.
    assert d.without.rms_error["random"] / d.one_shot_rms_error["random"] >= 10.0
    zero = simulate("acceleration", np.zeros(8000), seed=1).output[1000:]
    floor = float(np.sqrt(np.mean(zero**2)))
    for history in d.refine_rms_error.values():
        assert np.all((np.diff(history) < 0) | (history[1:] < 1.2 * floor))
        assert history[-1] < 1.2 * floor or history[-1] < history[0]
    # The complete model carries its known factors, so its JSON is self-contained.
    assert "known_factors" in d.model.meta
    assert d.inverse.has_known


def test_plot_and_figures(position_demo, tmp_path):
    fig = plot_demo(position_demo, tmp_path / "p.png")
    assert (tmp_path / "p.png").stat().st_size > 0
    assert len(fig.axes) == 4
    figures = position_demo.figures()
    assert figures["loop"] == "position"
    assert np.isfinite(figures["improvement"]["random"])
    assert "random" in position_demo.summary()


@pytest.mark.slow
def test_cli_demo_writes_report(tmp_path, capsys):
    out = tmp_path / "report"
    assert main(["compensate-demo", "--loop", "position", "--out", str(out), "--seed", "1",
                 "--duration", "8"]) == 0
    names = sorted(p.name for p in out.iterdir())
    assert names == ["position_compensation.json", "position_compensation.png",
                     "position_compensation_frf.csv", "position_compensation_traces.csv"]
    assert "position loop" in capsys.readouterr().out
