"""Plot of a simulated test: reference and output, drive, chamber pressures."""

from __future__ import annotations

from pathlib import Path

from ehss._files import atomic_path
from ehss.simulation.core import SimulationResult

__all__ = ["plot_simulation"]

_SCALE = {"m": (1e3, "mm")}  # others are drawn in their own unit


def plot_simulation(result: SimulationResult, path: str | Path | None = None, *, title=None):
    """Draw reference vs output, the drive and the chamber pressures.

    Parameters
    ----------
    result : SimulationResult
    path : str or Path, optional
        If given, the figure is saved there (atomically, format from the suffix) and closed.
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=(9, 7), constrained_layout=True)
    ax_ref, ax_drive, ax_p = fig.subplots(3, 1, sharex=True)
    scale, unit = _SCALE.get(result.units["output"], (1.0, result.units["output"]))
    t = result.t
    ax_ref.plot(t, result.reference * scale, label="reference", lw=1.0)
    ax_ref.plot(t, result.output * scale, label="measured output", lw=1.0)
    ax_ref.set_ylabel(f"{result.loop} ({unit})")
    ax_ref.legend(loc="best")
    ax_drive.plot(t, result.signals["drive_v"], lw=0.8, color="C2")
    ax_drive.set_ylabel(f"drive ({result.units['drive_v']})")
    ax_p.plot(t, result.signals["p1_pa"] / 1e6, label="P1", lw=0.8)
    ax_p.plot(t, result.signals["p2_pa"] / 1e6, label="P2", lw=0.8)
    ax_p.set_ylabel("pressure (MPa)")
    ax_p.set_xlabel("time (s)")
    ax_p.legend(loc="best")
    for ax in (ax_ref, ax_drive, ax_p):
        ax.grid(True, alpha=0.3)
    hits = result.limits_hit
    note = ", ".join(f"{k} {v:.1%}" for k, v in hits.items())
    fig.suptitle(title or f"ehss simulate: {result.loop} loop, fs = {result.fs:g} Hz"
                 + (f" (limits: {note})" if note else ""))
    if path is not None:
        path = Path(path)
        with atomic_path(path) as tmp:
            fig.savefig(tmp, format=path.suffix.lstrip(".") or "png", dpi=110)
    return fig
