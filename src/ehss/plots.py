"""Comparison plots: Bode of models against the H1 estimate, time responses, convergence.

The figures follow the paper's Figs 13–15: the identified model's magnitude and phase
against the Hanning-window estimate on a logarithmic frequency axis, and the simulated
against the measured time response. Every function builds a
:class:`matplotlib.figure.Figure` without pyplot (safe under any backend and in threads),
returns it, accepts existing axes to draw into, and saves a PNG (dpi 120) atomically when
``path`` is given.

Drawing time goes to layout and tick text, and to long lines. So the figures made here
have fixed layouts (no layout engine, one draw per save), and every time series is drawn
through :func:`plot_series`, which keeps per pixel column only the samples that set what
the column shows (:func:`decimate_for_pixels`).
"""

from __future__ import annotations

import io
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from numpy.typing import ArrayLike

from ehss._files import atomic_path
from ehss.errors import DataError, ParameterError
from ehss.frequency import FrequencyResponse

if TYPE_CHECKING:
    from ehss.simulation import SimulationResult
    from ehss.validation import ResidualTests

__all__ = [
    "bode_compare",
    "time_compare",
    "theta_convergence",
    "residual_plot",
    "plot_simulation",
    "decimate_for_pixels",
    "plot_series",
    "fixed_layout",
    "png_bytes",
    "save_figure",
    "DPI",
]

#: Resolution of saved PNG files.
DPI = 120

_MODEL_COLOURS = ("tab:red", "tab:green", "tab:purple", "tab:orange", "tab:brown", "tab:pink")


# --------------------------------------------------------------------------- drawing fast
def _shown(text: str | None) -> str:
    """``text`` as a font can draw it: a file name that is not valid UTF-8 (its bytes
    kept by Python as surrogates) shows with the replacement character."""
    if not text:
        return ""
    return text.encode("utf-8", "surrogateescape").decode("utf-8", "replace")


def decimate_for_pixels(
    x: np.ndarray, y: np.ndarray, n_columns: int
) -> tuple[np.ndarray, np.ndarray]:
    """The samples of a line that set what each of ``n_columns`` pixel columns shows.

    The x range of the data is cut into ``n_columns`` equal columns; in each, the first,
    lowest, highest and last samples are kept, in their order. The kept line has the
    same lowest and highest value in every column as the full line, and joins its
    neighbours through the same first and last samples, so that drawn at that width it
    covers the same pixels.

    Parameters
    ----------
    x : array_like, shape (n,)
        Non-decreasing abscissa (time).
    y : array_like, shape (n,)
        Ordinate. A line with non-finite values is returned whole (its gaps matter).
    n_columns : int
        Pixel columns the x range covers.

    Returns
    -------
    x, y : ndarray
        The kept samples (the input itself when there is nothing to gain).
    """
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if x.shape != y.shape or x.ndim != 1:
        raise DataError(f"x has shape {x.shape}, y has {y.shape}; both must be 1-D alike")
    n_columns = int(n_columns)
    if n_columns < 1:
        raise ParameterError(f"n_columns={n_columns} must be at least 1")
    if x.size <= 4 * n_columns or not np.all(np.isfinite(y)):
        return x, y
    if not np.all(np.diff(x) >= 0):
        raise DataError("x must be finite and non-decreasing to be decimated")
    span = x[-1] - x[0]
    if not span > 0:
        return x, y
    col = np.minimum(((x - x[0]) * (n_columns / span)).astype(np.intp), n_columns - 1)
    first = np.flatnonzero(np.diff(col, prepend=-1))
    last = np.append(first[1:] - 1, x.size - 1)
    # Within each column (col is sorted), order by y: the column's first entry is its
    # lowest sample and its last entry its highest.
    by_y = np.lexsort((y, col))
    keep = np.unique(np.concatenate([first, last, by_y[first], by_y[last]]))
    return x[keep], y[keep]


def _pixel_columns(ax: Axes, dpi: float) -> int:
    """Pixel columns of ``ax`` at ``dpi``: the axes' own width when the figure's layout is
    fixed, the whole figure's when a layout engine may still widen the axes."""
    fig = _root_figure(ax)
    dpi = max(float(dpi), float(fig.dpi))
    width_in = fig.get_figwidth()
    if fig.get_layout_engine() is None:
        width_in *= ax.get_position().width
    return max(1, math.ceil(width_in * dpi))


def _root_figure(ax: Axes) -> Figure:
    fig = ax.figure
    while not isinstance(fig, Figure):  # a SubFigure: its root
        fig = fig.figure
    return fig


def plot_series(
    ax: Axes, x: ArrayLike, y: ArrayLike, fmt: str | None = None, *, dpi: float = DPI, **kwargs: Any
) -> list[Line2D]:
    """``ax.plot(x, y, fmt, **kwargs)`` with the line decimated to the pixels it covers
    (:func:`decimate_for_pixels`) when saved at up to ``dpi``."""
    xd, yd = decimate_for_pixels(np.asarray(x), np.asarray(y), _pixel_columns(ax, dpi))
    args = (xd, yd) if fmt is None else (xd, yd, fmt)
    return ax.plot(*args, **kwargs)


def fixed_layout(
    fig: Figure, *, left: float, right: float, bottom: float, top: float,
    wspace: float = 0.0, hspace: float = 0.0,
) -> None:
    """Place the subplots by margins in inches (no layout engine: one draw per save).

    ``left``, ``right``, ``bottom`` and ``top`` are the margins from the figure's edges;
    ``wspace`` and ``hspace`` the gaps between subplots, all in inches.
    """
    w, h = fig.get_size_inches()
    fig.set_layout_engine(None)
    n_rows, n_cols = 1, 1
    for ax in fig.axes:
        spec = ax.get_subplotspec()
        if spec is not None:
            n_rows, n_cols = spec.get_gridspec().get_geometry()
            break
    inner_w = w - left - right - (n_cols - 1) * wspace
    inner_h = h - top - bottom - (n_rows - 1) * hspace
    fig.subplots_adjust(
        left=left / w, right=1.0 - right / w, bottom=bottom / h, top=1.0 - top / h,
        wspace=wspace / (inner_w / n_cols), hspace=hspace / (inner_h / n_rows),
    )


def png_bytes(fig: Figure, *, dpi: int = DPI) -> bytes:
    """The figure as PNG bytes, drawn once.

    A figure that still has a layout engine (constrained layout) has it run once and
    then fixed, so that saving does not lay it out and draw it twice.
    """
    buf = io.BytesIO()
    _save_once(fig, buf, dpi=dpi, fmt="png")
    return buf.getvalue()


def _save_once(fig: Figure, target: Path | io.BytesIO, *, dpi: int, fmt: str) -> None:
    engine = fig.get_layout_engine()
    if engine is not None:
        fig.set_dpi(dpi)  # lay out for the pixels it is saved at
        engine.execute(fig)
        fig.set_layout_engine(None)
    fig.savefig(target, dpi=dpi, format=fmt)


def save_figure(fig: Figure, path: str | Path, *, dpi: int = DPI) -> Path:
    """Save ``fig`` to ``path`` atomically (format from the suffix, default PNG), drawn once."""
    path = Path(path)
    fmt = path.suffix.lstrip(".").lower() or "png"
    with atomic_path(path) as tmp:
        _save_once(fig, tmp, dpi=dpi, fmt=fmt)
    return path


def _figure_for(ax: Axes | None, figsize: tuple[float, float], *,
                left: float) -> tuple[Figure, Axes]:
    """``ax`` and its figure, or a new figure of one axes with a fixed layout (``left``
    margin in inches for the y labels)."""
    if ax is not None:
        return _root_figure(ax), ax
    fig = Figure(figsize=figsize)
    new_ax = fig.subplots()
    fixed_layout(fig, left=left, right=0.2, bottom=0.55, top=0.35)
    return fig, new_ax


def _finished(fig: Figure, path: str | Path | None, *, suptitle: str | None = None) -> Figure:
    """``fig`` with its title, saved to ``path`` when one is given."""
    if suptitle:
        fig.suptitle(_shown(suptitle))
    if path is not None:
        save_figure(fig, path)
    return fig


def _as_models(models: Any) -> dict[str, Any]:
    if models is None:
        return {}
    if isinstance(models, Mapping):
        return dict(models)
    if hasattr(models, "frequency_response"):
        return {"model": models}
    raise ParameterError(
        f"models must be a model or a dict of name to model, got {type(models).__name__}"
    )


def bode_compare(
    frf: FrequencyResponse,
    models: Any = None,
    *,
    band_hz: tuple[float, float] | None = None,
    min_coherence: float = 0.9,
    title: str | None = None,
    axes: Sequence[Axes] | None = None,
    path: str | Path | None = None,
) -> Figure:
    """Bode magnitude (dB) and phase (deg) of models against the H1 estimate.

    Parameters
    ----------
    frf : FrequencyResponse
        Non-parametric estimate (:func:`ehss.frequency.h1_estimate`); drawn as a black
        line, faded where the coherence is below ``min_coherence``.
    models : ArmaxModel or dict of str to ArmaxModel, optional
        Models drawn over the estimate (anything with ``frequency_response(freq_hz)``).
    band_hz : (float, float), optional
        Validation band, shaded.
    min_coherence : float, default 0.9
        Coherence below which H1 points are faded.
    title : str, optional
        Figure title.
    axes : sequence of 3 Axes, optional
        Magnitude, phase and coherence axes to draw into (a new figure otherwise).
    path : str or Path, optional
        Save the figure there (PNG, dpi 120).

    Returns
    -------
    Figure
    """
    models = _as_models(models)
    fig: Figure
    if axes is None:
        fig = Figure(figsize=(8.0, 7.5))
        ax_m, ax_p, ax_c = fig.subplots(
            3, 1, sharex=True, gridspec_kw={"height_ratios": [3, 3, 1.3]}
        )
        fixed_layout(fig, left=0.85, right=0.2, bottom=0.55, top=0.55 if title else 0.2,
                     hspace=0.15)
    else:
        if len(axes) != 3:
            raise ParameterError(f"axes must be 3 Axes (magnitude, phase, coherence), "
                                 f"got {len(axes)}")
        ax_m, ax_p, ax_c = axes
        fig = _root_figure(ax_m)
    keep = frf.freq_hz > 0
    f = frf.freq_hz[keep]
    if f.size == 0:
        raise DataError("the frequency response has no positive frequencies to plot")
    mag = frf.magnitude_db[keep]
    phase = frf.phase_deg[keep]
    coh = frf.coherence[keep]
    good = coh >= min_coherence
    # Estimate: faint everywhere, solid where it is reliable.
    ax_m.semilogx(f, mag, color="0.75", lw=0.8)
    ax_p.semilogx(f, phase, color="0.75", lw=0.8)
    label = (f"H1 estimate (Hann, {frf.n_averages} averages)" if frf.method == "welch" else
             f"H1 from the record's DFT ({frf.n_averages} bins averaged)")
    ax_m.semilogx(f, np.where(good, mag, np.nan), color="k", lw=1.2, label=label)
    ax_p.semilogx(f, np.where(good, phase, np.nan), color="k", lw=1.2)
    ref_idx = int(np.flatnonzero(good)[0]) if good.any() else 0
    for i, (name, model) in enumerate(models.items()):
        g = np.asarray(model.frequency_response(f), dtype=np.complex128)
        colour = _MODEL_COLOURS[i % len(_MODEL_COLOURS)]
        with np.errstate(divide="ignore"):
            g_db = 20.0 * np.log10(np.abs(g))
        g_ph = np.degrees(np.unwrap(np.angle(g)))
        # Put the model's phase on the same 360° branch as the estimate.
        g_ph += 360.0 * np.round((phase[ref_idx] - g_ph[ref_idx]) / 360.0)
        ax_m.semilogx(f, g_db, color=colour, lw=1.2, ls="--", label=name)
        ax_p.semilogx(f, g_ph, color=colour, lw=1.2, ls="--")
    # Axis limits from the reliable part of the estimate, so that noise where nothing was
    # excited, a model zero on the unit circle (-inf dB) or an empty Nyquist bin does not
    # squash the plot.
    ref_mag, ref_ph = (mag[good], phase[good]) if good.any() else (mag, phase)
    finite = ref_mag[np.isfinite(ref_mag)]
    lo_db, hi_db = np.percentile(finite, [1.0, 100.0]) if finite.size else (-60.0, 20.0)
    ax_m.set_ylim(lo_db - 15.0, hi_db + 10.0)
    ax_p.set_ylim(float(np.min(ref_ph)) - 90.0, float(np.max(ref_ph)) + 90.0)
    ax_c.semilogx(f, coh, color="tab:blue", lw=1.0)
    ax_c.axhline(min_coherence, color="tab:blue", ls=":", lw=0.8)
    ax_c.set_ylim(0.0, 1.05)
    if band_hz is not None:
        for ax in (ax_m, ax_p, ax_c):
            ax.axvspan(max(band_hz[0], f[0]), band_hz[1], color="tab:green", alpha=0.08)
    ax_m.set_ylabel("magnitude (dB)")
    ax_p.set_ylabel("phase (deg)")
    ax_c.set_ylabel("coherence γ²")
    ax_c.set_xlabel("frequency (Hz)")
    ax_c.set_xlim(f[0], f[-1])
    for ax in (ax_m, ax_p, ax_c):
        ax.grid(True, which="both", lw=0.3, alpha=0.6)
    ax_m.legend(loc="best", fontsize=8)
    return _finished(fig, path, suptitle=title)


def time_compare(
    t: ArrayLike,
    measured: ArrayLike,
    simulated: Mapping[str, ArrayLike] | ArrayLike,
    *,
    window_s: tuple[float, float] | float | None = None,
    ylabel: str = "output",
    title: str | None = None,
    ax: Axes | None = None,
    path: str | Path | None = None,
) -> Figure:
    """Measured against simulated time responses on a time window.

    Parameters
    ----------
    t : array_like, shape (n_samples,)
        Time in seconds.
    measured : array_like, shape (n_samples,)
        The measured output.
    simulated : array_like or dict of str to array_like
        Model outputs on the same time base.
    window_s : (float, float) or float, optional
        Time window shown: ``(start, stop)`` in seconds, or a duration taken from the end
        of the record. Default: the whole record.
    ylabel, title : str
        Axis label (with its unit) and title.
    ax : Axes, optional
        Axes to draw into.
    path : str or Path, optional
        Save the figure there.

    Returns
    -------
    Figure
    """
    t = np.asarray(t, dtype=np.float64)
    measured = np.asarray(measured, dtype=np.float64)
    if not isinstance(simulated, Mapping):
        simulated = {"model": simulated}
    if measured.shape != t.shape:
        raise DataError(f"measured has shape {measured.shape}, t has {t.shape}")
    for name, v in simulated.items():
        if np.shape(v) != t.shape:
            raise DataError(f"simulated {name!r} has shape {np.shape(v)}, t has {t.shape}")
    sel = _time_window(t, window_s)
    fig, ax = _figure_for(ax, (8.0, 3.8), left=0.9)
    plot_series(ax, t[sel], measured[sel], color="k", lw=1.2, label="measured")
    for i, (name, v) in enumerate(simulated.items()):
        v = np.asarray(v, dtype=np.float64)
        plot_series(ax, t[sel], v[sel], color=_MODEL_COLOURS[i % len(_MODEL_COLOURS)],
                    lw=1.0, ls="--", label=name)
    ax.set_xlabel("time (s)")
    ax.set_ylabel(ylabel)
    ax.grid(True, lw=0.3, alpha=0.6)
    ax.legend(loc="best", fontsize=8)
    if title:
        ax.set_title(_shown(title))
    return _finished(fig, path)


def _time_window(t: np.ndarray, window_s: tuple[float, float] | float | None) -> np.ndarray:
    """Which samples of ``t`` the window holds: ``(start, stop)`` in s, a duration taken
    from the end, or (None) all of them."""
    if window_s is None:
        return np.ones(t.shape, dtype=bool)
    if isinstance(window_s, tuple | list):
        lo, hi = (float(v) for v in window_s)
    else:
        lo, hi = t[-1] - float(window_s), t[-1]
    sel = (t >= lo) & (t <= hi)
    if not np.any(sel):
        raise ParameterError(f"window {window_s} s holds no samples "
                             f"(record {t[0]:g}..{t[-1]:g} s)")
    return sel


def theta_convergence(
    history: ArrayLike,
    names: Sequence[str] | None = None,
    *,
    t: ArrayLike | None = None,
    ax: Axes | None = None,
    path: str | Path | None = None,
    title: str | None = None,
) -> Figure:
    """Parameter estimates against time (RELS convergence, eqs 20–22).

    Parameters
    ----------
    history : array_like, shape (n_samples, n_params)
        θ̂(k) row by row.
    names : sequence of str, optional
        Parameter names (e.g. ``a1, a2, b0, ...``); default ``θ1, θ2, ...``.
    t : array_like, shape (n_samples,), optional
        Time in seconds (default: sample index).
    """
    history = np.asarray(history, dtype=np.float64)
    if history.ndim == 1:
        history = history[:, None]
    if history.ndim != 2:
        raise DataError(f"history must be 2-D (n_samples, n_params), got {history.shape}")
    n, p = history.shape
    if names is None:
        names = [f"θ{i + 1}" for i in range(p)]
    if len(names) != p:
        raise ParameterError(f"{len(names)} names for {p} parameters")
    x = np.arange(n) if t is None else np.asarray(t, dtype=np.float64)
    if x.shape != (n,):
        raise DataError(f"t has shape {x.shape}, history has {n} samples")
    fig, ax = _figure_for(ax, (8.0, 4.2), left=0.8)
    for j in range(p):
        plot_series(ax, x, history[:, j], lw=1.0, label=names[j])
    ax.set_xlabel("sample" if t is None else "time (s)")
    ax.set_ylabel("estimate")
    ax.grid(True, lw=0.3, alpha=0.6)
    ax.legend(loc="best", fontsize=7, ncol=max(1, p // 6))
    ax.set_title(_shown(title or "parameter convergence"))
    return _finished(fig, path)


def residual_plot(
    tests: ResidualTests,
    *,
    axes: Sequence[Axes] | None = None,
    path: str | Path | None = None,
    title: str | None = None,
) -> Figure:
    """Residual autocorrelation and input–residual cross-correlation with their bounds.

    Parameters
    ----------
    tests : ResidualTests
        From :func:`ehss.validation.residual_tests`.
    axes : sequence of 2 Axes, optional
        Axes to draw into.
    """
    fig: Figure
    if axes is None:
        fig = Figure(figsize=(8.0, 5.5))
        ax_e, ax_x = fig.subplots(2, 1)
        fixed_layout(fig, left=0.7, right=0.2, bottom=0.55, top=0.65 if title else 0.35,
                     hspace=0.85)
    else:
        if len(axes) != 2:
            raise ParameterError(f"axes must be 2 Axes, got {len(axes)}")
        ax_e, ax_x = axes
        fig = _root_figure(ax_e)
    lags = tests.lags[1:]
    ax_e.stem(lags, tests.autocorrelation[1:], basefmt=" ")
    b = tests.autocorrelation_bound
    ax_e.fill_between([0, lags[-1] + 1], -b, b, color="tab:blue", alpha=0.12)
    verdict = "white" if tests.white else "not white"
    ax_e.set_title(f"residual autocorrelation ({verdict}, Ljung–Box p = "
                   f"{tests.ljung_box_p:.3g})", fontsize=10)
    ax_e.set_xlabel("lag (samples)")
    ax_x.stem(tests.cross_lags, tests.cross_correlation, basefmt=" ")
    c = tests.cross_bound
    ax_x.fill_between([tests.cross_lags[0] - 1, tests.cross_lags[-1] + 1], -c, c,
                      color="tab:blue", alpha=0.12)
    verdict = "independent" if tests.independent else "correlated"
    ax_x.set_title(f"input–residual cross-correlation ({verdict})", fontsize=10)
    ax_x.set_xlabel("lag (samples; > 0: past inputs)")
    for ax in (ax_e, ax_x):
        ax.grid(True, lw=0.3, alpha=0.6)
    return _finished(fig, path, suptitle=title)


_SCALE = {"m": (1e3, "mm")}  # others are drawn in their own unit


def plot_simulation(
    result: SimulationResult, path: str | Path | None = None, *, title: str | None = None
) -> Figure:
    """Draw reference vs output, the drive and the chamber pressures of one simulated test.

    Parameters
    ----------
    result : SimulationResult
    path : str or Path, optional
        If given, the figure is saved there (atomically, format from the suffix, dpi 110).
    title : str, optional

    Returns
    -------
    Figure
    """
    fig = Figure(figsize=(9, 7))
    ax_ref, ax_drive, ax_p = fig.subplots(3, 1, sharex=True)
    fixed_layout(fig, left=0.85, right=0.2, bottom=0.55, top=0.45, hspace=0.15)
    scale, unit = _SCALE.get(result.units["output"], (1.0, result.units["output"]))
    t = result.t
    plot_series(ax_ref, t, result.reference * scale, label="reference", lw=1.0)
    plot_series(ax_ref, t, result.output * scale, label="measured output", lw=1.0)
    ax_ref.set_ylabel(f"{result.loop} ({unit})")
    ax_ref.legend(loc="best")
    plot_series(ax_drive, t, result.signals["drive_v"], lw=0.8, color="C2")
    ax_drive.set_ylabel(f"drive ({result.units['drive_v']})")
    plot_series(ax_p, t, result.signals["p1_pa"] / 1e6, label="P1", lw=0.8)
    plot_series(ax_p, t, result.signals["p2_pa"] / 1e6, label="P2", lw=0.8)
    ax_p.set_ylabel("pressure (MPa)")
    ax_p.set_xlabel("time (s)")
    ax_p.legend(loc="best")
    for ax in (ax_ref, ax_drive, ax_p):
        ax.grid(True, alpha=0.3)
    hits = result.limits_hit
    note = ", ".join(f"{k} {v:.1%}" for k, v in hits.items())
    fig.suptitle(_shown(title) or f"ehss simulate: {result.loop} loop, fs = {result.fs:g} Hz"
                 + (f" (limits: {note})" if note else ""))
    if path is not None:
        save_figure(fig, path, dpi=110)
    return fig
