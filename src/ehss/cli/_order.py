"""``ehss order``: compare model orders by validation fit (and AIC, FPE, MDL columns).

Every candidate is fitted with the estimator ``ehss identify`` uses (same ``--method``
vocabulary, same estimation part), ranked by its free-run fit on held-out data (the end
of the record, or a separate ``--validate`` file), never recommending an unstable
model, and the exact ``ehss identify`` command for the pick is printed.
"""

from __future__ import annotations

import argparse
import copy
import math
import shlex
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
from ehss.cli._outputs import InputFile, OutputTable
from ehss.errors import ParameterError

__all__ = ["register", "run"]

_COLUMNS = ("na", "nb", "nc", "delay", "n_params", "loss", "aic", "fpe", "mdl", "fit_pct",
            "stable", "max_pole_radius")
_DEFAULT_HOLDOUT = 0.3
_METHOD_HELP = ("arx: least squares; armax: prediction-error minimisation from extended "
                "least squares; oe: output error by prediction-error minimisation (nc is "
                "ignored); rels: the paper's recursive extended least squares; rml: recursive "
                "maximum likelihood")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "order",
        help="order-selection table (held-out fit, AIC, FPE, MDL) over a grid of orders",
        description="Fit every combination of the candidate orders to the first part of the "
        "record with the estimator identify will use, score each by its free-run fit on "
        "the held-out end (or on --validate FILE) and by AIC, FPE and MDL on its one-step "
        "prediction errors, print the table, the best stable candidate and the ehss "
        "identify command that refits it. Lists are like 2,3,4 or 2-6.",
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
    p.add_argument("--criterion", choices=("fit", "aic", "fpe", "mdl"),
                   help="how the best is chosen (default: fit, the free-run fit on the "
                   "validation data, when there are any; else aic)")
    p.add_argument("--method", default="armax", choices=("arx", "armax", "oe", "rels", "rml"),
                   help=f"estimator for each candidate, as in identify: {_METHOD_HELP} "
                   "(default: %(default)s)")
    p.add_argument("--init", default="batch", choices=("batch", "zero"),
                   help="start of rels/rml: from the batch estimate (default) or the "
                   "paper's zero start")
    p.add_argument("--holdout", type=float, metavar="FRACTION",
                   help="fraction at the end kept for the fit column; 0 uses all data "
                   "for estimation and leaves fit empty (default: 0.3)")
    p.add_argument("--validate", metavar="FILE", type=InputFile,
                   help="validate on this separate record (same column options) instead of "
                   "the held-out end; the whole DATA is then used for estimation")
    p.add_argument("--out", metavar="TABLE.csv", type=OutputTable,
                   help="also write the table: .csv (with a .json sidecar), .parquet, .h5, "
                   ".npz or .mat")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ehss.identification.order import select_order

    holdout = 0.0 if args.validate is not None else holdout_fraction(
        _DEFAULT_HOLDOUT if args.holdout is None else args.holdout)
    if args.validate is not None and args.holdout is not None:
        raise ParameterError("--holdout and --validate exclude each other: the separate "
                             "record is the validation data")
    has_validation = args.validate is not None or holdout > 0.0
    if args.criterion == "fit" and not has_validation:
        raise ParameterError("--criterion fit needs --holdout > 0 or --validate FILE")
    criterion = args.criterion or ("fit" if has_validation else "aic")
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
    if args.validate is not None:
        vargs = copy.copy(args)
        vargs.data = args.validate
        val = load_record(vargs)
        if not math.isclose(val.fs, rec.fs, rel_tol=1e-6):
            raise ParameterError(f"--validate {args.validate!r} is sampled at {val.fs:g} Hz, "
                                 f"DATA at {rec.fs:g} Hz; they must match")
        # each record about its own operating point (means removed separately)
        validation = (val.u - float(np.mean(val.u)), val.y - float(np.mean(val.y)))
    with report_warnings("order"):
        sel = select_order(
            u[:n_est], y[:n_est], na=args.na, nb=args.nb, nc=args.nc, delay=args.delay,
            dt=1.0 / rec.fs, criterion=criterion, validation=validation,
            method=args.method, init=args.init,
        )
    _print_table(sel, rec, args, n_est)
    print(f"refit and validate it with:\n  {identify_command(args, sel, holdout)}")
    if args.out is not None:
        cols = {c: np.array([_value(r, c) for r in sel.table], dtype=np.float64)
                for c in _COLUMNS}
        from ehss._provenance import versions
        from ehss.io import table_writers

        sidecar = {
            "what": f"order selection {args.input} -> {args.output}",
            "data": str(rec.path),
            "validate": args.validate,
            "method": args.method,
            "init": args.init,
            "criterion": criterion,
            "n_estimation_samples": n_est,
            "best": {"na": sel.best.na, "nb": sel.best.nb, "nc": sel.best.nc,
                     "delay": sel.best.delay},
            "identify_command": identify_command(args, sel, holdout),
            "versions": versions(),
        }
        out = Path(args.out)
        write_outputs(table_writers(out, cols, sidecar))
    return 0


def identify_command(args: argparse.Namespace, sel, holdout: float) -> str:
    """The ``ehss identify`` command line that refits the pick the same way."""
    b = sel.best
    cmd = ["ehss", "identify", str(args.data), "--input", args.input, "--output", args.output]
    if args.fs is not None:
        cmd += ["--fs", repr(args.fs)]
    if args.time_column != "t":
        cmd += ["--time-column", args.time_column]
    cmd += ["--na", str(b.na), "--nb", str(b.nb), "--nc", str(b.nc), "--delay", str(b.delay),
            "--method", args.method]
    if args.method in ("rels", "rml") and args.init != "batch":
        cmd += ["--init", args.init]
    if args.validate is not None:
        cmd += ["--validate", str(args.validate)]
    else:
        cmd += ["--holdout", repr(holdout)]
    cmd += ["--out", "MODEL.json"]
    return shlex.join(cmd)


def _value(row, column: str) -> float:
    return float(row.fit if column == "fit_pct" else getattr(row, column))


def _fit_text(fit: float) -> str:
    if math.isnan(fit):
        return ""
    return "diverges" if fit == -math.inf else f"{fit:.2f}"


def _print_table(sel, rec, args, n_est: int) -> None:
    from rich.console import Console
    from rich.table import Table

    where = (f"validated on {Path(args.validate).name}" if args.validate is not None
             else "validated on the held-out end")
    table = Table(title=f"Orders for {args.input} → {args.output} ({rec.path.name}, "
                  f"{n_est} estimation samples, {args.method}, {where})")
    for c in ("", "na", "nb", "nc", "delay", "params", "loss", "AIC", "FPE", "MDL", "fit %",
              "max |pole|"):
        table.add_column(c, justify="right")
    for r in sel.table:
        mark = "★" if r is sel.best else ("unstable" if not r.stable else "")
        table.add_row(mark, str(r.na), str(r.nb), str(r.nc), str(r.delay), str(r.n_params),
                      f"{r.loss:.6g}", f"{r.aic:.6g}", f"{r.fpe:.6g}", f"{r.mdl:.6g}",
                      _fit_text(r.fit), f"{r.max_pole_radius:.4f}")
    console = Console(width=140, highlight=False)
    console.print(table)
    b = sel.best
    console.print(f"best by {sel.criterion}: --na {b.na} --nb {b.nb} --nc {b.nc} "
                  f"--delay {b.delay} (method {sel.method}; unstable candidates are never "
                  "recommended)")
