"""Compensation on the simulated rig (default tunings): the paper's working bands."""

from __future__ import annotations

import numpy as np
import pytest

from ehss.cli import main
from ehss.compensation import demonstrate, plot_demo


@pytest.fixture(scope="module")
def position_demo():
    return demonstrate("position", seed=0, duration_s=16.0, iterations=2)


@pytest.mark.slow
def test_position_loop_within_1db_5deg_and_10x(position_demo):
    d = position_demo
    assert d.judge_hz == (1.0, 20.0)
    assert d.max_abs_db_with <= 1.0
    assert d.max_abs_deg_with <= 5.0
    assert d.improvement["random"] >= 10.0
    # The uncompensated loop is far from it, so the test is not trivially met.
    assert d.max_abs_deg_without > 5.0


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason=(
    "the 6th-order RELS model identified at 1 kHz on the 2-100 Hz random test does not "
    "capture the 0.5 Hz acceleration-generator high-pass (the loop leads by 54 deg at 1 Hz, "
    "the model by -2 deg); the inverse and its learning iterations leave about "
    "±3.5 dB / ±13 deg at 1-2 Hz and a 7.8x RMS improvement"))
def test_acceleration_loop_within_1db_5deg_and_10x():
    d = demonstrate("acceleration", seed=0, duration_s=16.0, iterations=2)
    assert d.judge_hz == (1.0, 50.0)
    assert d.max_abs_db_with <= 1.0
    assert d.max_abs_deg_with <= 5.0
    assert d.improvement["random"] >= 10.0


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
