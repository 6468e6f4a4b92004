"""``ehss order``: compare model orders the way ``ehss identify`` validates one.

A thin adapter over :func:`ehss.workflow.select_orders`: the record is prepared once as
``ehss identify`` prepares it (held-out end or ``--validate FILE``, ``--detrend``,
``--decimate``, ``--band``), every candidate is fitted with the estimator ``identify``
uses (same ``--method`` vocabulary) and validated as ``identify`` validates, ranked by that
fit (AIC, FPE and MDL are columns; the verdict too), never recommending an unstable model;
the exact ``ehss identify`` command that refits the pick is printed, and running it
reports the same fit. What is not given follows the record: the band of interest from
the input's spectrum, the delays (and nb) from its impulse response where each half of
the record agrees, else over the response's rise (:func:`ehss.identification.delay.
scan_delays`); the messages say delays at the record's rate and at the model's.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import shlex
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ehss.cli import add_command
from ehss.cli._dataargs import (
    add_record_arguments,
    int_list,
    load_record,
    load_validation,
    report_warnings,
    write_outputs,
)
from ehss.cli._options import add_options, build_options
from ehss.cli._outputs import InputFile, OutputTable
from ehss.errors import DataError, ParameterError

if TYPE_CHECKING:
    from ehss.cli._dataargs import Record
    from ehss.identification.delay import DelayScan
    from ehss.workflow import OrderGrid, OrderSearch, Preparation, Prepared

__all__ = ["register", "run", "identify_command"]

_COLUMNS = ("na", "nb", "nc", "delay", "n_params", "loss", "aic", "fpe", "mdl", "fit_pct",
            "simulation_fit_pct", "stable", "max_pole_radius", "accepted")
_METHOD_HELP = ("arx: least squares; armax: prediction-error minimisation from extended "
                "least squares; oe: output error by prediction-error minimisation (nc is "
                "ignored); rels: the paper's recursive extended least squares; rml: recursive "
                "maximum likelihood")


#: ``ehss order``'s own help of the preparation's flags
_PREPARATION_HELP = {
    "validation": "fraction at the end of the record kept for validation (default: "
    "0.3, or none with --validate)",
    "band_hz": "band of interest (Hz), as in identify: the fit is scored there and the "
    "decimation aims at it (default: the band the input excites, where its power spectrum "
    "is within 20 dB of its peak, read once the decimation is chosen from the record's "
    "content; the identify command printed carries it and the factor)",
    "decimate": "decimate an oversampled record by N before fitting, as identify does "
    "(default: %(default)s)",
}


def register(sub: argparse._SubParsersAction) -> None:
    from ehss.workflow import Estimation, Evaluation, OrderGrid, Preparation

    p = add_command(
        sub, "order",
        description="Prepare the record as ehss identify does (held-out end or --validate "
        "FILE, detrend, decimation), fit every combination of the candidate orders with "
        "the estimator identify will use, validate each as identify does (free-run fit on "
        "the validation data; AIC, FPE and MDL on the one-step prediction errors of the "
        "estimation data; the verdict), print the table, the best stable candidate and the "
        "ehss identify command that refits it with the same fit. Lists are like 2,3,4 or "
        "2-6.",
    )
    add_record_arguments(p)
    grid = OrderGrid()  # low orders, as most loops of a rig are at the model's rate
    p.add_argument("--na", type=int_list, default=list(grid.na), metavar="LIST",
                   help="candidate orders of A (default: 1-4)")
    p.add_argument("--nb", type=int_list, metavar="LIST",
                   help="candidate orders of B (default: 0-3, or up to 6 to span the "
                   "response's rise when the record does not support a delay estimate)")
    p.add_argument("--nc", type=int_list, default=list(grid.nc), metavar="LIST",
                   help="candidate orders of C (default: 1-2)")
    p.add_argument("--delay", type=int_list, metavar="LIST",
                   help="candidate input delays in samples of the record (default: the "
                   "delay estimated from the prepared record's impulse response and the "
                   "one a sample of the model's rate shorter, when each half of the record "
                   "gives the same; else up to 4 delays over the response's rise)")
    add_options(p, OrderGrid)
    add_options(p, Estimation, help={"method": f"estimator for each candidate, as in "
                                     f"identify: {_METHOD_HELP} (default: %(default)s)",
                                     "init": "start of rels/rml: from the batch estimate or "
                                     "the paper's zero start (default: %(default)s)"})
    add_options(p, Preparation, help=_PREPARATION_HELP)
    p.add_argument("--validate", metavar="FILE", type=InputFile,
                   help="validate on this separate record (same column options and sample "
                   "rate) instead of the held-out end; the whole DATA is then estimation data")
    add_options(p, Evaluation, only=("initial",))
    p.add_argument("--out", metavar="TABLE.csv", type=OutputTable,
                   help="also write the table: .csv (with a .json sidecar), .parquet, .h5, "
                   ".npz or .mat")
    p.set_defaults(func=run)


def _check_args(args: argparse.Namespace) -> None:
    if args.validate is not None and args.holdout is not None:
        raise ParameterError("give either --holdout or --validate, not both: the separate "
                             "record is the validation data")
    for name in ("na", "nb", "nc", "delay"):
        low = 1 if name == "na" else 0
        bad = [v for v in getattr(args, name) or [] if v < low]
        if bad:
            raise ParameterError(f"--{name} {bad[0]} must be >= {low}")
    n_grid = _grid(args).size
    if n_grid > 500:
        raise ParameterError(f"the grid has {n_grid} candidates; keep it to 500 or fewer")
    _preparation(args, None)


def _grid(args: argparse.Namespace) -> OrderGrid:
    from ehss.workflow import OrderGrid

    return build_options(args, OrderGrid, na=args.na, nb=args.nb, nc=args.nc,
                         delay=args.delay)


def _preparation(args: argparse.Namespace,
                 validation: tuple[Any, Any] | None) -> Preparation:
    """The preparation the flags ask for; without --band, the band the input excites."""
    from ehss.workflow import Preparation

    given = {} if validation is None else {"validation": validation}
    prep = build_options(args, Preparation, **given)
    return prep if prep.band_hz is not None else dataclasses.replace(prep, band_hz="input")


def run(args: argparse.Namespace) -> int:
    from ehss.workflow import Estimation, Evaluation, select_orders

    _check_args(args)
    rec = load_record(args)
    val = load_validation(args, rec)
    preparation = _preparation(args, None if val is None else (val.u, val.y))
    args.band_given = args.band is not None
    from rich.console import Console

    console = Console(stderr=True)
    with report_warnings("order"), console.status("preparing the record") as status:
        progress = _Progress(status, tty=console.is_terminal)
        try:
            search = select_orders(
                rec.u, rec.y, fs=rec.fs, grid=_grid(args), preparation=preparation,
                estimation=build_options(args, Estimation),
                evaluation=build_options(args, Evaluation, only=("initial",)),
                progress=progress,
            )
        except DataError as exc:
            if args.delay is None and "to estimate a delay" in str(exc):
                raise DataError(f"{exc} with --delay") from None
            raise
    if not args.band_given:
        _say_input_band(args, search.prepared)
    if search.delay_scan is not None:
        print(_delay_message(search, search.delay_scan), file=sys.stderr)
    command = identify_command(args, search)
    _print_table(search, rec, args)
    if not any(v is not None and v.accepted for v in search.verdicts):
        p = search.prepared
        rate = ("" if p.decimation == 1 or args.band is not None else
                f", or fit at a higher rate than {p.fs_model:g} Hz (--decimate N below "
                f"{p.decimation}: near its Nyquist frequency a sampled model of a loop "
                "with a dead time misses) or judge only the band of interest (--band LO "
                "HI)")
        verdict = search.verdicts[search.best_index]
        failed = "; ".join(verdict.failed) if verdict is not None else ""
        print(f"no candidate meets the acceptance (the pick fails: "
              f"{failed or 'not validated'}); "
              f"widen the grid, or record more data ({p.u.size} estimation samples)"
              f"{rate}", file=sys.stderr)
    print(f"refit and validate it with:\n  {command}")
    if args.out is not None:
        cols = {c: np.array([_value(search, i, c) for i in range(len(search.table))],
                            dtype=np.float64) for c in _COLUMNS}
        from ehss._provenance import versions
        from ehss.io import table_writers

        p = search.prepared
        na, nb, nc, d = search.best_orders
        sidecar = {
            "what": f"order selection {args.input} -> {args.output}",
            "data": str(rec.path),
            "validate": args.validate,
            "holdout": preparation.holdout,
            "method": args.method,
            "init": args.init,
            "criterion": args.criterion,
            "detrend": preparation.detrend,
            "decimation": p.decimation,
            "fs_data_hz": p.fs,
            "fs_model_hz": p.fs_model,
            "band_hz": None if args.band is None else list(args.band),
            "band_from": "--band" if args.band_given else "the input's spectrum",
            "delay_scan": None if search.delay_scan is None else {
                "supported": search.delay_scan.supported,
                "whole": search.delay_scan.whole,
                "halves": list(search.delay_scan.halves),
                "rise_10_50_pct": (None if search.delay_scan.rise is None
                                   else list(search.delay_scan.rise)),
                "unit": "samples of the model"},
            "initial_state": args.initial,
            "n_estimation_samples": int(p.u.size),
            "n_validation_samples": int(p.u_val.size),
            "delay_column": "samples of the record",
            "best": {"na": na, "nb": nb, "nc": nc, "delay": d},
            "identify_command": command,
            "versions": versions(),
        }
        write_outputs(table_writers(Path(args.out), cols, sidecar))
    return 0


class _Progress:
    """How far the search is: a spinner on a terminal; elsewhere (a log, a pipe) a line
    on stderr at every tenth of a grid of 20 candidates or more."""

    def __init__(self, status: Any, *, tty: bool) -> None:
        self.status, self.tty, self.done = status, tty, 0

    def __call__(self, line: str) -> None:
        self.done += 1
        text = f"fitted {self.done} candidates; last {line}"
        if self.tty:
            self.status.update(text)
        elif self.done % 20 == 0:
            print(f"ehss order: {text}", file=sys.stderr, flush=True)


def _say_input_band(args: argparse.Namespace, prepared: Prepared) -> None:
    """Say the band read from the input's spectrum, and carry it (with the decimation
    chosen before it was read) into the identify command."""
    from ehss.preprocess import EXCITATION_LEVEL_DB

    band = prepared.band_hz
    if band is None:
        return
    args.band = band
    if prepared.decimation > 1 and args.decimate.strip().lower() == "auto":
        args.decimate = str(prepared.decimation)  # the band would change auto's factor
    print(f"band of interest read from the input's spectrum: {band[0]:.4g}-{band[1]:.4g} "
          f"Hz (where its power is within {EXCITATION_LEVEL_DB:g} dB of its peak, below "
          f"what the decimation leaves untouched; --band LO HI sets it)", file=sys.stderr)


def _delay_message(search: OrderSearch, scan: DelayScan) -> str:
    """What the record said about its delay and which delays were tried, at both rates."""
    from ehss.workflow import delay_text

    p = search.prepared
    q = p.decimation

    def samples(d_model: int) -> str:  # model samples, and the record's when decimated
        if q == 1:
            return f"{d_model} samples"
        return f"{d_model} samples of the model at {p.fs_model:g} Hz ({d_model * q} at " \
               f"{p.fs:g} Hz)"

    tried = ", ".join(str(d) for d in sorted(set(search.delays)))
    nbs = sorted({r.nb for r in search.table})
    nb = f"nb {nbs[0]}-{nbs[-1]}" if len(nbs) > 1 else f"nb {nbs[0]}"
    if scan.supported and scan.delay is not None:
        return (f"{delay_text(scan.delay * q, decimation=q, fs=p.fs)} estimated from the "
                "record's impulse response (each half gives the same); trying delays "
                f"{tried} samples of the record (--delay sets the candidates)")
    found = [d for d in (scan.whole, *scan.halves) if d is not None]
    if found:
        how = (f"the whole record and its halves place it at {scan.whole}, "
               f"{scan.halves[0]} and {scan.halves[1]} samples"
               f"{'' if q == 1 else ' of the model'}")
    else:
        how = (f"no tap up to {samples(scan.max_delay)} stands out of the noise, in the "
               "whole record or its halves")
    rise = ("" if scan.rise is None else
            f"; its step response reaches 10 % of its peak at {samples(scan.rise[0])} and "
            f"50 % at {samples(scan.rise[1])}")
    return (f"the record does not pin its delay down ({how}){rise}: trying delays {tried} "
            f"samples of the record with {nb} (--delay and --nb set the candidates)")


def identify_command(args: argparse.Namespace, search: OrderSearch) -> str:
    """The ``ehss identify`` command line that refits the pick of ``search`` (the result
    of :func:`ehss.workflow.select_orders` for ``args``) with every setting that affects
    the model and its fit."""
    na, nb, nc, d = search.best_orders
    cmd = ["ehss", "identify", str(args.data), "--input", args.input, "--output", args.output]
    if args.fs is not None:
        cmd += ["--fs", repr(args.fs)]
    if args.time_column != "t":
        cmd += ["--time-column", args.time_column]
    cmd += ["--na", str(na), "--nb", str(nb), "--nc", str(nc), "--delay", str(d),
            "--method", args.method]
    if args.method in ("rels", "rml"):
        cmd += ["--init", args.init]
    if args.validate is not None:
        cmd += ["--validate", str(args.validate)]
    else:
        cmd += ["--holdout", repr(search.prepared.holdout)]
    cmd += ["--detrend", args.detrend, "--decimate", str(args.decimate).strip().lower()]
    if args.band is not None:
        cmd += ["--band", repr(args.band[0]), repr(args.band[1])]
    if args.initial != "estimate":
        cmd += ["--initial", args.initial]
    cmd += ["--out", "MODEL.json"]
    return shlex.join(cmd)


def _value(search: OrderSearch, i: int, column: str) -> float:
    row = search.table[i]
    rep, verdict = search.reports[i], search.verdicts[i]
    if column == "delay":
        return float(search.delays[i])
    if column == "fit_pct":
        return float(row.fit)
    if column == "simulation_fit_pct":
        return math.nan if rep is None else float(rep.simulation_fit_pct)
    if column == "accepted":
        return math.nan if verdict is None else float(verdict.accepted)
    return float(getattr(row, column))


def _fit_text(fit: float | None) -> str:
    from ehss.validation import DIVERGED_FIT_PCT

    if fit is None or math.isnan(fit):
        return ""
    return "diverges" if not math.isfinite(fit) or fit < DIVERGED_FIT_PCT else f"{fit:.2f}"


def _print_table(search: OrderSearch, rec: Record, args: argparse.Namespace) -> None:
    from rich.console import Console
    from rich.table import Table

    from ehss.validation import fit_text

    p = search.prepared
    where = (f"validated on {Path(args.validate).name}" if args.validate is not None
             else f"validated on the held-out {p.holdout:g}")
    rate = (f", decimated by {p.decimation} to {p.fs_model:g} Hz, delays in samples of "
            f"the record at {p.fs:g} Hz" if p.decimation > 1 else "")
    table = Table(title=f"Orders for {args.input} → {args.output} ({rec.path.name}, "
                  f"{p.u.size} estimation samples{rate}, {args.method}, {where})")
    band = p.band_hz is not None and any(r is not None and r.band_fit_pct is not None
                                         for r in search.reports)
    heads = ["", "na", "nb", "nc", "delay", "params", "loss", "AIC", "FPE", "MDL", "fit %"]
    heads += ["band fit %"] if band else []
    heads += ["max |pole|", "verdict"]
    for c in heads:
        table.add_column(c, justify="right")
    for i, r in enumerate(search.table):
        rep, verdict = search.reports[i], search.verdicts[i]
        mark = "★" if r is search.best else ("unstable" if not r.stable else "")
        cells = [mark, str(r.na), str(r.nb), str(r.nc), str(search.delays[i]),
                 str(r.n_params), f"{r.loss:.6g}", f"{r.aic:.6g}", f"{r.fpe:.6g}",
                 f"{r.mdl:.6g}", _fit_text(None if rep is None else rep.simulation_fit_pct)]
        if band:
            cells.append(_fit_text(None if rep is None else rep.band_fit_pct))
        cells += [f"{r.max_pole_radius:.4f}",
                  "" if verdict is None else ("accepted" if verdict.accepted else "no")]
        table.add_row(*cells)
    console = Console(width=150, highlight=False)
    console.print(table)
    na, nb, nc, d = search.best_orders
    rep = search.reports[search.best_index]
    assert rep is not None  # the pick is a stable candidate, always validated
    fit = f"simulation fit {fit_text(rep.simulation_fit_pct)}"
    if rep.band_fit_pct is not None:
        fit += f", in the band {fit_text(rep.band_fit_pct)}"
    verdict = search.verdicts[search.best_index]
    among = ("the best that meets the acceptance" if verdict is not None
             and verdict.accepted else "none meets the acceptance")
    from ehss.workflow import delay_text

    delay = "" if p.decimation == 1 else (
        f"{delay_text(d, decimation=p.decimation, fs=p.fs)}; ")
    console.print(f"best by {search.selection.criterion}: --na {na} --nb {nb} --nc {nc} "
                  f"--delay {d} ({delay}method {search.method}; {fit}; {among}; never "
                  "unstable)")
