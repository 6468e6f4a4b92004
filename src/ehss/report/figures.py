"""Figures of the reproduction report, laid out like the paper's Figs 12–15.

Layouts are fixed (margins in inches, :func:`ehss.plots.fixed_layout`) and time series
are drawn to the pixels they cover (:func:`ehss.plots.plot_series`): each figure is laid
out and drawn once when saved.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from ehss.experiments import ACCEPTANCE, CompensationDemo, LoopResult, StepTest, plot_demo
from ehss.plots import (
    bode_compare,
    fixed_layout,
    plot_series,
    png_bytes,
    theta_convergence,
    time_compare,
)

__all__ = [
    "step_figure",
    "loop_figure",
    "convergence_figure",
    "compensation_figure",
    "render_png",
    "LOOP_UNITS",
    "REPORT_DPI",
]

#: Resolution of the report's PNG figures.
REPORT_DPI = 110

LOOP_UNITS = {
    "position": ("displacement", "mm", 1e3),
    "acceleration": ("acceleration", "m/s²", 1.0),
    "force": ("force", "N", 1.0),
}


def step_figure(steps: dict[str, StepTest]) -> Figure:
    """Fig. 12: step responses of the three loops with their targets."""
    fig = Figure(figsize=(11, 3.4))
    axes = fig.subplots(1, len(steps))
    fixed_layout(fig, left=0.65, right=0.1, bottom=0.5, top=0.6, wspace=0.75)
    for ax, (loop, st) in zip(np.atleast_1d(axes), steps.items(), strict=True):
        label, unit, scale = LOOP_UNITS[loop]
        r = st.result
        plot_series(ax, r.t, st.target * scale, "k--", dpi=REPORT_DPI, lw=1.0, label="target")
        plot_series(ax, r.t, r.output * scale, dpi=REPORT_DPI, lw=1.2, label="measured")
        m = st.metrics
        ax.set_title(
            f"{loop}: rise {m.rise_time_s * 1e3:.0f} ms, overshoot {m.overshoot_pct:.0f} %",
            fontsize=9,
        )
        ax.set_xlabel("time (s)")
        ax.set_ylabel(f"{label} ({unit})")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle("Step tests of the three loops (cf. Fig. 12)")
    return fig


def loop_figure(res: LoopResult, *, title: str, window_s: float = 1.0) -> Figure:
    """Figs 13–15: (a) time response, (b) magnitude and (c) phase of the models vs H1.

    The paper-order model is drawn, and, when it fails the acceptance, the simplest model
    that meets it. The Bode panels are :func:`ehss.plots.bode_compare`'s.
    """
    label, unit, scale = LOOP_UNITS[res.setup.loop]
    checks = [res.paper] + ([res.passing] if res.passing is not None else [])
    fig = Figure(figsize=(11, 8.5))
    gs = fig.add_gridspec(3, 2, height_ratios=[3, 3, 1.2])
    ax_t = fig.add_subplot(gs[0, :])
    ax_m = fig.add_subplot(gs[1, 0])
    ax_p = fig.add_subplot(gs[1, 1], sharex=ax_m)
    ax_c = fig.add_subplot(gs[2, :])
    fixed_layout(fig, left=0.75, right=0.15, bottom=0.5, top=0.8, wspace=0.75, hspace=0.75)

    sim = res.sim
    fs = res.record.frf.fs
    i0 = res.record.n_ident
    i1 = min(sim.t.size, i0 + int(round(window_s * fs)))
    window = (sim.t[i0], sim.t[i1 - 1])
    plot_series(ax_t, sim.t[i0:i1], sim.reference[i0:i1] * scale, dpi=REPORT_DPI,
                color="0.7", lw=0.8, label="reference")
    time_compare(
        sim.t,
        sim.output * scale,
        {f"{c.label}: fit {c.fit_pct:.1f} %": c.simulated * scale for c in checks},
        window_s=window,
        ylabel=f"{label} ({unit})",
        title="(a) time response on held-out data",
        ax=ax_t,
    )
    ax_t.legend(fontsize=8, loc="upper right")

    band = res.paper.error.band_hz
    models = {
        f"{c.label}: {c.error.max_magnitude_db:.2f} dB, {c.error.max_phase_deg:.1f}°": c.model
        for c in checks
    }
    # Above the band the reference has no content and H1 means nothing: stop there.
    bode_compare(res.record.frf.band(0.0, band[1]), models, band_hz=band, axes=(ax_m, ax_p, ax_c))
    ax_m.set_title(f"(b) magnitude (max errors vs the held-out H1 where γ² ≥ "
                   f"{ACCEPTANCE.min_coherence:g})", fontsize=10)
    ax_p.set_title("(c) phase", fontsize=10)
    ax_m.legend(fontsize=7, loc="lower left")
    ax_p.set_xlabel("frequency (Hz)")
    ax_m.set_xlabel("frequency (Hz)")
    fig.suptitle(title)
    return fig


def convergence_figure(loops: dict[str, LoopResult]) -> Figure:
    """θ̂(k) of each paper-order model during its estimation record (RELS, eqs 20–22)."""
    fig = Figure(figsize=(11, 3.6))
    axes = np.atleast_1d(fig.subplots(1, len(loops)))
    fixed_layout(fig, left=0.75, right=0.1, bottom=0.5, top=0.6, wspace=0.95)
    for ax, (name, r) in zip(axes, loops.items(), strict=True):
        m = r.paper.model
        names = ([f"a{i}" for i in range(1, m.na + 1)] + [f"b{i}" for i in range(m.nb + 1)]
                 + [f"c{i}" for i in range(1, m.nc + 1)])
        # b is in physical units (m/m, (m/s²)/(m/s²), N/N); all of θ share one axis.
        theta_convergence(r.theta_history, names, t=r.theta_t, ax=ax, title=f"{name} loop")
        ax.get_legend().remove() if ax.get_legend() is not None else None
    fig.suptitle("Convergence of the RELS estimates θ̂ = [a, b, c] (eqs 20–22)")
    return fig


def compensation_figure(demo: CompensationDemo) -> Figure:
    """Figs 16–17: :func:`ehss.experiments.plot_demo`'s 2 × 2 panels, laid out fixed."""
    fig = plot_demo(demo)
    # A fixed layout for the 2 × 2 panels: saved with one draw, no layout engine.
    fixed_layout(fig, left=0.85, right=0.15, bottom=0.5, top=0.35, wspace=0.95, hspace=0.75)
    return fig


def render_png(make: Callable[..., Figure], /, *args: Any, **kwargs: Any) -> bytes:
    """``make(*args, **kwargs)`` as PNG bytes at :data:`REPORT_DPI`.

    A module-level function of picklable arguments, so that a figure can be drawn in
    another process (:func:`ehss.experiments.pool.submit`).
    """
    return png_bytes(make(*args, **kwargs), dpi=REPORT_DPI)
