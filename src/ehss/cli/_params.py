"""``ehss params``: print a parameter set with units, or save it as TOML."""

from __future__ import annotations

import argparse

from ehss.cli._outputs import InputFile, OutputFile
from ehss.params import PRESETS, describe_params, load_params, preset, save_params

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "params",
        help="print a parameter set with units (or save it as TOML)",
        description="Print a parameter set with units and the derived quantities of the "
        "linear model (ωh, ζh, Kh, ω0, ζ0, ωr, ωm, ζm, K0).",
    )
    src = p.add_mutually_exclusive_group()
    src.add_argument("--preset", default="default", choices=sorted(PRESETS),
                     help="named parameter set (default: %(default)s)")
    src.add_argument("--params", metavar="FILE.toml", type=InputFile,
                     help="read a (partial) TOML parameter file")
    p.add_argument("--save", metavar="FILE.toml", type=OutputFile,
                   help="write the parameter set as TOML")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from rich.console import Console
    from rich.table import Table

    params = load_params(args.params) if args.params else preset(args.preset)
    if args.save:
        save_params(params, args.save)
    table = Table(title=f"ehss parameters: {params.name}", show_lines=False)
    for col in ("section", "parameter", "value", "unit"):
        table.add_column(col, justify="right" if col == "value" else "left")
    for row in describe_params(params):
        table.add_row(*row)
    Console(width=110).print(table)
    return 0
