"""``ehss order``: compare ARMAX orders with AIC, FPE or MDL (and held-out fit)."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from ehss.cli._dataargs import (
    add_record_arguments,
    holdout_fraction,
    int_list,
    load_record,
    report_warnings,
    write_outputs,
)
from ehss.cli._outputs import OutputTable
from ehss.errors import ParameterError

__all__ = ["register", "run"]

_COLUMNS = ("na", "nb", "nc", "delay", "n_params", "loss", "aic", "fpe", "mdl", "fit_pct")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "order",
        help="order-selection table (AIC, FPE, MDL, held-out fit) over a grid of ARMAX orders",
        description="Fit every combination of the candidate orders to the first part of the "
        "record, score each by AIC, FPE and MDL on its one-step prediction errors and by "
        "the simulation fit on the held-out end, and print the table and the best. Lists "
        "are like 2,3,4 or 2-6.",
    )
    add_record_arguments(p)
    p.add_argument("--na", type=int_list, required=True, metavar="LIST",
                   help="candidate orders of A")
    p.add_argument("--nb", type=int_list, required=True, metavar="LIST",
                   help="candidate orders of B")
    p.add_argument("--nc", type=int_list, required=True, metavar="LIST",
                   help="candidate orders of C")
    p.add_argument("--delay", type=int_list, default=[1], metavar="LIST",
                   help="candidate input delays in samples (default: 1)")
    p.add_argument("--criterion", default="aic", choices=("aic", "fpe", "mdl", "fit"),
                   help="how the best is chosen (default: %(default)s; fit = held-out "
                   "simulation fit)")
    p.add_argument("--method", default="els", choices=("els", "rels"),
                   help="estimator for each candidate: batch extended least squares or "
                   "RELS (default: %(default)s)")
    p.add_argument("--holdout", type=float, default=0.3, metavar="FRACTION",
                   help="fraction at the end kept for the fit column; 0 uses all data "
                   "for estimation and leaves fit empty (default: %(default)s)")
    p.add_argument("--out", metavar="TABLE.csv", type=OutputTable,
                   help="also write the table: .csv (with a .json sidecar), .parquet, .h5, "
                   ".npz or .mat")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ehss.identification.order import select_order

    holdout = holdout_fraction(args.holdout)
    if args.criterion == "fit" and holdout == 0.0:
        raise ParameterError("--criterion fit needs --holdout > 0")
    n_grid = len(args.na) * len(args.nb) * len(args.nc) * len(args.delay)
    if n_grid > 500:
        raise ParameterError(f"the grid has {n_grid} candidates; keep it to 500 or fewer")
    rec = load_record(args)
    n = rec.u.size
    n_est = int(round(n * (1.0 - holdout)))
    u_mean = float(np.mean(rec.u[:n_est]))
    y_mean = float(np.mean(rec.y[:n_est]))
    u, y = rec.u - u_mean, rec.y - y_mean
    validation = None if holdout == 0.0 else (u[n_est:], y[n_est:])
    with report_warnings("order"):
        sel = select_order(
            u[:n_est], y[:n_est], na=args.na, nb=args.nb, nc=args.nc, delay=args.delay,
            dt=1.0 / rec.fs, criterion=args.criterion, validation=validation,
            method=args.method,
        )
    _print_table(sel, rec, args, n_est)
    if args.out is not None:
        cols = {c: np.array([_value(r, c) for r in sel.table], dtype=np.float64)
                for c in _COLUMNS}
        from ehss._provenance import versions
        from ehss.io import table_writers

        sidecar = {
            "what": f"order selection {args.input} -> {args.output}",
            "data": str(rec.path),
            "method": args.method,
            "criterion": args.criterion,
            "n_estimation_samples": n_est,
            "best": {"na": sel.best.na, "nb": sel.best.nb, "nc": sel.best.nc,
                     "delay": sel.best.delay},
            "versions": versions(),
        }
        out = Path(args.out)
        write_outputs(table_writers(out, cols, sidecar))
    return 0


def _value(row, column: str) -> float:
    return float(row.fit if column == "fit_pct" else getattr(row, column))


def _print_table(sel, rec, args, n_est: int) -> None:
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"ARMAX orders for {args.input} → {args.output} ({rec.path.name}, "
                  f"{n_est} estimation samples, {args.method})")
    for c in ("", "na", "nb", "nc", "delay", "params", "loss", "AIC", "FPE", "MDL", "fit %"):
        table.add_column(c, justify="right")
    for r in sel.table:
        mark = "★" if r is sel.best else ""
        fit = "" if math.isnan(r.fit) else f"{r.fit:.2f}"
        table.add_row(mark, str(r.na), str(r.nb), str(r.nc), str(r.delay), str(r.n_params),
                      f"{r.loss:.6g}", f"{r.aic:.6g}", f"{r.fpe:.6g}", f"{r.mdl:.6g}", fit)
    console = Console(width=120, highlight=False)
    console.print(table)
    b = sel.best
    console.print(f"best by {args.criterion}: --na {b.na} --nb {b.nb} --nc {b.nc} "
                  f"--delay {b.delay}")
