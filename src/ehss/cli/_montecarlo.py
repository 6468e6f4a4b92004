"""``ehss montecarlo``: how the compensation holds across a rig's uncertain parameters.

A thin adapter over :func:`ehss.campaign.montecarlo`.
"""

from __future__ import annotations

import argparse

from ehss.cli import add_command
from ehss.cli._batch import add_cluster_arguments, check_cluster_arguments
from ehss.cli._outputs import InputFile, OutputFolder

__all__ = ["register", "run"]


def register(sub: argparse._SubParsersAction) -> None:
    p = add_command(
        sub, "montecarlo",
        description="Draw N samples of the rig's uncertain parameters (distributions in "
        "TOML; Sobol or Latin hypercube, seeded) and, per sample on the simulated rig, "
        "identify the loop, then track one test reference without compensation, with the "
        "nominal model's inverse and with the sample's own model's inverse. Writes one row "
        "per sample (OUT/tasks/), OUT/summary.html with the distributions and the fraction "
        "of samples that meet the acceptance. A re-run skips the samples already done.",
        epilog="example: ehss montecarlo robustness.toml --samples 500 --out mc",
    )
    p.add_argument("spec", type=InputFile, metavar="SPEC.toml",
                   help="parameter distributions and settings (README: Campaigns)")
    p.add_argument("--out", type=OutputFolder, required=True, metavar="DIR",
                   help="campaign folder (created; an earlier run there is resumed)")
    p.add_argument("--samples", type=int, metavar="N", help="replaces the file's samples")
    p.add_argument("--seed", type=int, metavar="N", help="replaces the file's seed")
    add_cluster_arguments(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import json
    from pathlib import Path

    import polars as pl

    from ehss.campaign import montecarlo

    check_cluster_arguments(args)
    frame = montecarlo(args.spec, args.out, scheduler=args.scheduler, workers=args.workers,
                       quiet=args.quiet, connect_timeout_s=args.connect_timeout,
                       samples=args.samples, seed=args.seed)
    outcome = json.loads((Path(args.out) / "settings.json").read_text())["outcome"]
    failed = frame.filter(pl.col("status") != "ok").height
    print(f"ehss montecarlo: {outcome['text']}; {failed} failed; rows in {args.out}/tasks/, "
          f"summary {args.out}/summary.html")
    return 0
