"""Plots are produced under Agg, saved atomically, and are non-trivial PNG files."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal
from matplotlib.figure import Figure

from ehss.errors import DataError, ParameterError
from ehss.frequency import h1_estimate
from ehss.identification.model import ArmaxModel
from ehss.plots import (
    bode_compare,
    decimate_for_pixels,
    fixed_layout,
    plot_series,
    plot_simulation,
    png_bytes,
    residual_plot,
    theta_convergence,
    time_compare,
)
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


# --------------------------------------------------------------------------- decimation
def _columns(x, n_columns):
    """Pixel column of each sample, by comparison with the column edges (slow, obvious)."""
    edges = x[0] + (x[-1] - x[0]) * np.arange(1, n_columns) / n_columns
    return np.array([int(np.sum(xi >= edges)) for xi in x])


def test_decimated_line_has_the_full_lines_envelope_in_every_column(rng):
    # 20 011 samples over 97 columns: no sample but the two ends falls on a column edge,
    # so the edge comparison above and the decimation agree on every sample's column.
    n, n_columns = 20_011, 97
    x = np.arange(n) / 1000.0
    y = np.cumsum(rng.standard_normal(n))
    y[rng.integers(0, n, 40)] += rng.choice([-50.0, 50.0], 40)  # isolated spikes
    xd, yd = decimate_for_pixels(x, y, n_columns)
    assert xd.size <= 4 * n_columns < n
    # The kept samples are samples of the line, in order, ends included.
    idx = np.searchsorted(x, xd)
    assert np.all(np.diff(idx) > 0) and idx[0] == 0 and idx[-1] == n - 1
    assert np.array_equal(y[idx], yd)
    col, col_d = _columns(x, n_columns), _columns(xd, n_columns)
    for c in range(n_columns):
        full, kept = y[col == c], yd[col_d == c]
        # Same lowest and highest value, and the same first and last sample, so the
        # segments joining neighbouring columns are the full line's own.
        assert kept.min() == full.min() and kept.max() == full.max()
        assert kept[0] == full[0] and kept[-1] == full[-1]


def test_decimation_leaves_short_or_gapped_lines_whole(rng):
    x = np.arange(100.0)
    y = rng.standard_normal(100)
    assert np.array_equal(decimate_for_pixels(x, y, 25)[1], y)  # 4 per column: no gain
    xl = np.arange(10_000.0)
    yl = rng.standard_normal(10_000)
    yl[500] = np.nan  # a gap must stay a gap
    assert np.array_equal(decimate_for_pixels(xl, yl, 10)[0], xl)
    with pytest.raises(ParameterError, match="n_columns"):
        decimate_for_pixels(x, y, 0)
    with pytest.raises(DataError, match="non-decreasing"):
        decimate_for_pixels(xl[::-1], rng.standard_normal(10_000), 10)


def test_time_series_are_drawn_decimated_to_the_axes_width(tmp_path, rng):
    fig = Figure(figsize=(5.0, 3.0))
    ax = fig.subplots()
    fixed_layout(fig, left=1.0, right=0.5, bottom=0.5, top=0.5)
    # The axes are 3.5 in wide: at 120 dpi, 420 pixel columns.
    pos = ax.get_position()
    assert pos.x0 * 5.0 == pytest.approx(1.0) and pos.width * 5.0 == pytest.approx(3.5)
    assert pos.y0 * 3.0 == pytest.approx(0.5) and pos.height * 3.0 == pytest.approx(2.0)
    t = np.arange(100_000) / 1000.0
    y = rng.standard_normal(t.size)
    (line,) = plot_series(ax, t, y, dpi=120)
    xd, yd = decimate_for_pixels(t, y, 420)
    assert np.array_equal(line.get_xdata(), xd) and np.array_equal(line.get_ydata(), yd)
    assert 420 < xd.size <= 4 * 420


def test_png_of_a_constrained_figure_is_laid_out_once():
    fig = Figure(figsize=(4.0, 3.0), layout="constrained")
    ax = fig.subplots()
    ax.plot([0, 1], [0, 1])
    ax.set_ylabel("a long label that needs room")
    data = png_bytes(fig, dpi=50)
    assert data[:8] == PNG_MAGIC
    assert fig.get_layout_engine() is None  # its positions are now fixed
    assert ax.get_position().x0 > 0.1  # and were laid out: room for the label


def test_plot_simulation_png(tmp_path):
    from ehss import preset, simulate

    fs = 1000.0
    ref = np.sin(2 * np.pi * 2.0 * np.arange(int(2 * fs)) / fs) * 1e-3
    run = simulate("position", ref, params=preset("default"), seed=0)
    fig = plot_simulation(run, tmp_path / "run.png")
    assert len(fig.axes) == 3
    # 2000 samples on 7.95 in at 110 dpi (875 columns): drawn decimated, still whole.
    line = fig.axes[0].lines[0]
    assert line.get_xdata()[0] == run.t[0] and line.get_xdata()[-1] == run.t[-1]
    _assert_png(tmp_path / "run.png")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.png"]
