"""Plots are produced under Agg, saved atomically, and are non-trivial PNG files."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal

from ehss.errors import DataError, ParameterError
from ehss.frequency import h1_estimate
from ehss.identification.model import ArmaxModel
from ehss.plots import bode_compare, residual_plot, theta_convergence, time_compare
from ehss.validation import residual_tests

FS = 1000.0
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture
def case(rng):
    model = ArmaxModel(a=[1.0, -1.5, 0.7], b=[0.1, 0.1], c=[1.0], delay=1, dt=1 / FS)
    u = rng.standard_normal(8000)
    y = model.simulate(u) + 0.01 * rng.standard_normal(u.size)
    return model, u, y


def _assert_png(path, min_kb=10):
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC
    assert len(data) > min_kb * 1024  # a real figure with lines and text, not an empty one


def test_bode_compare_png(tmp_path, case):
    model, u, y = case
    frf = h1_estimate(u, y, FS)
    other = ArmaxModel(a=[1.0, -1.4, 0.6], b=[0.1, 0.1], c=[1.0], delay=1, dt=1 / FS)
    fig = bode_compare(frf, {"model": model, "other": other}, band_hz=(1, 100),
                       title="position loop", path=tmp_path / "bode.png")
    assert len(fig.axes) == 3
    assert fig.axes[2].get_xscale() == "log"
    _assert_png(tmp_path / "bode.png", min_kb=30)
    # A single model is accepted as well; nothing left behind but the outputs.
    bode_compare(frf, model, path=tmp_path / "one.png")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bode.png", "one.png"]


def test_bode_compare_bad_models(case, rng):
    model, u, y = case
    frf = h1_estimate(u, y, FS)
    with pytest.raises(ParameterError, match="models"):
        bode_compare(frf, 3)


def test_time_compare_png(tmp_path, case):
    model, u, y = case
    t = np.arange(u.size) / FS
    fig = time_compare(t, y, {"model": model.simulate(u)}, window_s=(1.0, 1.5),
                       ylabel="displacement (m)", path=tmp_path / "time.png")
    line = fig.axes[0].lines[0]
    assert line.get_xdata().min() >= 1.0 and line.get_xdata().max() <= 1.5
    _assert_png(tmp_path / "time.png", min_kb=15)
    fig = time_compare(t, y, model.simulate(u), window_s=0.25)
    assert fig.axes[0].lines[0].get_xdata().min() >= t[-1] - 0.25
    with pytest.raises(ParameterError, match="holds no samples"):
        time_compare(t, y, y, window_s=(100, 200))
    with pytest.raises(DataError, match="shape"):
        time_compare(t, y[:-1], y)


def test_theta_convergence_png(tmp_path, rng):
    hist = np.cumsum(rng.standard_normal((500, 4)), axis=0) / 100
    theta_convergence(hist, ["a1", "a2", "b0", "c1"], t=np.arange(500) / FS,
                      path=tmp_path / "theta.png")
    _assert_png(tmp_path / "theta.png")
    with pytest.raises(ParameterError, match="names"):
        theta_convergence(hist, ["a1"])


def test_residual_plot_png(tmp_path, case):
    model, u, y = case
    res = residual_tests(model, u, y)
    fig = residual_plot(res, path=tmp_path / "resid.png")
    assert len(fig.axes) == 2
    _assert_png(tmp_path / "resid.png")


def test_plot_to_missing_folder_leaves_nothing(tmp_path, case):
    model, u, y = case
    frf = h1_estimate(u, scipy.signal.lfilter([1.0], [1.0], y), FS)
    with pytest.raises(DataError, match="does not exist"):
        bode_compare(frf, model, path=tmp_path / "no" / "bode.png")
    assert list(tmp_path.iterdir()) == []
