"""Comparison plots: Bode of models against the H1 estimate, time responses, convergence.

The figures follow the paper's Figs 13–15: the identified model's magnitude and phase
against the Hanning-window estimate on a logarithmic frequency axis, and the simulated
against the measured time response. Every function builds a
:class:`matplotlib.figure.Figure` without pyplot (safe under any backend and in threads),
returns it, accepts existing axes to draw into, and saves a PNG (dpi 120) atomically when
``path`` is given.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from ehss._files import atomic_path
from ehss.errors import DataError, ParameterError
from ehss.frequency import FrequencyResponse

__all__ = [
    "bode_compare",
    "time_compare",
    "theta_convergence",
    "residual_plot",
    "save_figure",
    "DPI",
]

#: Resolution of saved PNG files.
DPI = 120

_MODEL_COLOURS = ("tab:red", "tab:green", "tab:purple", "tab:orange", "tab:brown", "tab:pink")


def save_figure(fig: Figure, path: str | Path, *, dpi: int = DPI) -> Path:
    """Save ``fig`` to ``path`` atomically (format from the suffix, default PNG)."""
    path = Path(path)
    fmt = path.suffix.lstrip(".").lower() or "png"
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi, format=fmt, bbox_inches="tight")
    return path


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
    if axes is None:
        fig = Figure(figsize=(8.0, 7.5), layout="constrained")
        ax_m, ax_p, ax_c = fig.subplots(
            3, 1, sharex=True, gridspec_kw={"height_ratios": [3, 3, 1.3]}
        )
    else:
        if len(axes) != 3:
            raise ParameterError(f"axes must be 3 Axes (magnitude, phase, coherence), "
                                 f"got {len(axes)}")
        ax_m, ax_p, ax_c = axes
        fig = ax_m.figure
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
    if title:
        fig.suptitle(title)
    if path is not None:
        save_figure(fig, path)
    return fig


def time_compare(
    t,
    measured,
    simulated: Mapping[str, Any] | Any,
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
    if window_s is None:
        sel = slice(None)
    else:
        if np.isscalar(window_s):
            lo, hi = t[-1] - float(window_s), t[-1]
        else:
            lo, hi = (float(v) for v in window_s)
        sel = (t >= lo) & (t <= hi)
        if not np.any(sel):
            raise ParameterError(f"window {window_s} s holds no samples "
                                 f"(record {t[0]:g}..{t[-1]:g} s)")
    if ax is None:
        fig = Figure(figsize=(8.0, 3.8), layout="constrained")
        ax = fig.subplots()
    else:
        fig = ax.figure
    ax.plot(t[sel], measured[sel], color="k", lw=1.2, label="measured")
    for i, (name, v) in enumerate(simulated.items()):
        v = np.asarray(v, dtype=np.float64)
        ax.plot(t[sel], v[sel], color=_MODEL_COLOURS[i % len(_MODEL_COLOURS)], lw=1.0,
                ls="--", label=name)
    ax.set_xlabel("time (s)")
    ax.set_ylabel(ylabel)
    ax.grid(True, lw=0.3, alpha=0.6)
    ax.legend(loc="best", fontsize=8)
    if title:
        ax.set_title(title)
    if path is not None:
        save_figure(fig, path)
    return fig


def theta_convergence(
    history,
    names: Sequence[str] | None = None,
    *,
    t=None,
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
    if ax is None:
        fig = Figure(figsize=(8.0, 4.2), layout="constrained")
        ax = fig.subplots()
    else:
        fig = ax.figure
    for j in range(p):
        ax.plot(x, history[:, j], lw=1.0, label=names[j])
    ax.set_xlabel("sample" if t is None else "time (s)")
    ax.set_ylabel("estimate")
    ax.grid(True, lw=0.3, alpha=0.6)
    ax.legend(loc="best", fontsize=7, ncol=max(1, p // 6))
    ax.set_title(title or "parameter convergence")
    if path is not None:
        save_figure(fig, path)
    return fig


def residual_plot(
    tests: Any,
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
    if axes is None:
        fig = Figure(figsize=(8.0, 5.5), layout="constrained")
        ax_e, ax_x = fig.subplots(2, 1)
    else:
        if len(axes) != 2:
            raise ParameterError(f"axes must be 2 Axes, got {len(axes)}")
        ax_e, ax_x = axes
        fig = ax_e.figure
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
    if title:
        fig.suptitle(title)
    if path is not None:
        save_figure(fig, path)
    return fig
