"""``ehss params``: print a parameter set with units and its loops' stability, retune
the loops for the rig it describes, or save it as TOML."""

from __future__ import annotations

import argparse
import dataclasses
from typing import TYPE_CHECKING

from ehss.cli import add_command
from ehss.cli._outputs import InputFile, OutputFile
from ehss.params import PRESETS, RigParams, describe_params, load_params, preset, save_params

if TYPE_CHECKING:
    from ehss.linear import Margins

__all__ = ["register", "loop_check", "warn_if_unstable"]


def register(sub: argparse._SubParsersAction) -> None:
    p = add_command(
        sub, "params",
        description="Print a parameter set with units, the derived quantities of the "
        "linear model (ωh, ζh, Kh, ω0, ζ0, ωr, ωm, ζm, K0) and the stability of the three "
        "sampled loops (closed-loop pole radius, gain and phase margins of the linearised "
        "loop). A rig of other mass, valve or actuator needs its own controller gains: "
        "--tune designs them as the defaults were (6.5 dB gain margin on the sampled loop).",
        epilog="example: ehss params --params heavy.toml --tune --save heavy_tuned.toml",
    )
    src = p.add_mutually_exclusive_group()
    src.add_argument("--preset", default="default", choices=sorted(PRESETS),
                     help="named parameter set (default: %(default)s)")
    src.add_argument("--params", metavar="FILE.toml", type=InputFile,
                     help="read a (partial) TOML parameter file")
    p.add_argument("--tune", action="store_true",
                   help="replace the position, acceleration (TVC) and force gains by a design "
                   "for this rig (ehss.control.tuning, 6.5 dB gain margin)")
    p.add_argument("--save", metavar="FILE.toml", type=OutputFile,
                   help="write the parameter set (tuned, with --tune) as TOML")
    p.set_defaults(func=run)


def loop_check(params: RigParams, loop: str) -> tuple[float, Margins]:
    """``(closed-loop pole radius, margins)`` of the linearised sampled ``loop``
    (:func:`ehss.linear.closed_loop_radius`, :func:`ehss.linear.margins`)."""
    from ehss import linear

    margins = linear.margins(linear.loop_gain(params, loop, discrete=True))
    return linear.closed_loop_radius(params, loop), margins


def unstable_loop(params: RigParams, loop: str, source: str) -> str | None:
    """Why ``loop``'s gains do not stabilise this rig (linearised), with the ``ehss
    params`` command that designs gains for it, or None when they do. ``source`` is how
    the command was given the parameters (``--params rig.toml``)."""
    from ehss import linear

    radius = linear.closed_loop_radius(params, loop)  # milliseconds; the margins' grid
    if radius < 1.0:                                  # takes 0.1-0.3 s, so only when
        return None                                   # they are printed
    m = linear.margins(linear.loop_gain(params, loop, discrete=True))
    return (f"the {loop} loop is unstable with these gains on this rig (linearised: "
            f"closed-loop pole radius {radius:.4f}, gain margin {m.gain_margin_db:.2f} dB); "
            f"`ehss params {source} --tune --save TUNED.toml` designs gains for it")


def warn_if_unstable(command: str, params: RigParams, loop: str, source: str) -> bool:
    """One line on stderr when ``loop``'s gains do not stabilise this rig (linearised);
    True if so. The run goes on: the nonlinear rig then shows a limit cycle or drifts to
    its limits, which is what such gains do, but not a response to its reference."""
    import sys

    why = unstable_loop(params, loop, source)
    if why is not None:
        print(f"ehss {command}: warning: {why}", file=sys.stderr)
    return why is not None


def _tuned(params: RigParams) -> RigParams:
    from ehss.control.tuning import tune_force, tune_position, tune_tvc

    return dataclasses.replace(params, position=tune_position(params),
                               acceleration=tune_tvc(params), force=tune_force(params))


def run(args: argparse.Namespace) -> int:
    from rich.console import Console
    from rich.table import Table

    from ehss.control.tuning import REQUIRED_GAIN_MARGIN_DB
    from ehss.linear import LOOPS

    params = load_params(args.params) if args.params else preset(args.preset)
    if args.tune:
        params = _tuned(params)
    if args.save:
        save_params(params, args.save)
    console = Console(width=110)
    table = Table(title=f"ehss parameters: {params.name}", show_lines=False)
    for col in ("section", "parameter", "value", "unit"):
        table.add_column(col, justify="right" if col == "value" else "left")
    for row in describe_params(params):
        table.add_row(*row)
    console.print(table)
    loops = Table(title="sampled loops, linearised" + (" (tuned)" if args.tune else ""))
    for col in ("loop", "pole radius", "gain margin", "phase margin", "verdict"):
        loops.add_column(col, justify="left" if col in ("loop", "verdict") else "right")
    for loop in LOOPS:
        radius, m = loop_check(params, loop)
        verdict = ("UNSTABLE" if radius >= 1.0 else
                   f"below {REQUIRED_GAIN_MARGIN_DB:g} dB"
                   if m.gain_margin_db < REQUIRED_GAIN_MARGIN_DB else "ok")
        loops.add_row(loop, f"{radius:.4f}", f"{m.gain_margin_db:.2f} dB",
                      f"{m.phase_margin_deg:.1f}°", verdict)
    console.print(loops)
    return 0
