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
import math
import shlex
import sys
from pathlib import Path

import numpy as np

from ehss._checks import check_band
from ehss.cli import command_help
from ehss.cli._dataargs import (
    add_record_arguments,
    int_list,
    load_record,
    load_validation,
    report_warnings,
    write_outputs,
)
from ehss.cli._identify import _decimate_arg
from ehss.cli._outputs import InputFile, OutputTable
from ehss.errors import DataError, ParameterError

__all__ = ["register", "run", "identify_command"]

_COLUMNS = ("na", "nb", "nc", "delay", "n_params", "loss", "aic", "fpe", "mdl", "fit_pct",
            "simulation_fit_pct", "stable", "max_pole_radius", "accepted")
_DEFAULT_HOLDOUT = 0.3
#: the grid searched when --na, --nb or --nc is not given: low orders, as most loops of a
#: rig are at the model's rate (the decimation brings the rate to ten times the band)
DEFAULT_NA, DEFAULT_NB, DEFAULT_NC = range(1, 5), range(0, 4), range(1, 3)
_METHOD_HELP = ("arx: least squares; armax: prediction-error minimisation from extended "
                "least squares; oe: output error by prediction-error minimisation (nc is "
                "ignored); rels: the paper's recursive extended least squares; rml: recursive "
                "maximum likelihood")


def register(sub: argparse._SubParsersAction) -> None:
    from ehss.identification import INITS, METHODS
    from ehss.workflow import DEFAULT_METHOD

    p = sub.add_parser(
        "order",
        help=command_help("order"),
        description="Prepare the record as ehss identify does (held-out end or --validate "
        "FILE, detrend, decimation), fit every combination of the candidate orders with "
        "the estimator identify will use, validate each as identify does (free-run fit on "
        "the validation data; AIC, FPE and MDL on the one-step prediction errors of the "
        "estimation data; the verdict), print the table, the best stable candidate and the "
        "ehss identify command that refits it with the same fit. Lists are like 2,3,4 or "
        "2-6.",
    )
    add_record_arguments(p)
    p.add_argument("--na", type=int_list, default=list(DEFAULT_NA), metavar="LIST",
                   help="candidate orders of A (default: 1-4)")
    p.add_argument("--nb", type=int_list, metavar="LIST",
                   help="candidate orders of B (default: 0-3, or up to 6 to span the "
                   "response's rise when the record does not support a delay estimate)")
    p.add_argument("--nc", type=int_list, default=list(DEFAULT_NC), metavar="LIST",
                   help="candidate orders of C (default: 1-2)")
    p.add_argument("--delay", type=int_list, metavar="LIST",
                   help="candidate input delays in samples of the record (default: the "
                   "delay estimated from the prepared record's impulse response and the "
                   "one a sample of the model's rate shorter, when each half of the record "
                   "gives the same; else up to 4 delays over the response's rise)")
    p.add_argument("--criterion", choices=("fit", "aic", "fpe", "mdl"), default="fit",
                   help="how the best is chosen: the free-run fit on the validation data "
                   "(the one identify reports), or an information criterion on the "
                   "estimation data (default: %(default)s)")
    p.add_argument("--method", default=DEFAULT_METHOD, choices=METHODS,
                   help=f"estimator for each candidate, as in identify: {_METHOD_HELP} "
                   "(default: %(default)s)")
    p.add_argument("--init", default="batch", choices=INITS,
                   help="start of rels/rml: from the batch estimate or the paper's zero "
                   "start (default: %(default)s)")
    p.add_argument("--holdout", type=float, metavar="FRACTION",
                   help="fraction at the end of the record kept for validation (default: "
                   f"{_DEFAULT_HOLDOUT}, or none with --validate)")
    p.add_argument("--validate", metavar="FILE", type=InputFile,
                   help="validate on this separate record (same column options and sample "
                   "rate) instead of the held-out end; the whole DATA is then estimation data")
    p.add_argument("--band", nargs=2, type=float, metavar=("LO", "HI"),
                   help="band of interest (Hz), as in identify: the fit is scored there and "
                   "the decimation aims at it (default: the band the input excites, where "
                   "its power spectrum is within 20 dB of its peak, read once the "
                   "decimation is chosen from the record's content; the identify command "
                   "printed carries it and the factor)")
    p.add_argument("--detrend", choices=("mean", "linear", "none"), default="mean",
                   help="remove the mean (operating point) or a straight line from the "
                   "estimation and the validation data (default: %(default)s)")
    p.add_argument("--decimate", default="auto", metavar="auto|none|N",
                   help="decimate an oversampled record by N before fitting, as identify "
                   "does (default: %(default)s)")
    p.add_argument("--initial", choices=("estimate", "zero"), default="estimate",
                   help="initial state of the validation simulation: least-squares "
                   "estimate or rest (default: %(default)s)")
    p.add_argument("--out", metavar="TABLE.csv", type=OutputTable,
                   help="also write the table: .csv (with a .json sidecar), .parquet, .h5, "
                   ".npz or .mat")
    p.set_defaults(func=run)


def _check_args(args: argparse.Namespace) -> dict:
    if args.validate is not None and args.holdout is not None:
        raise ParameterError("give either --holdout or --validate, not both: the separate "
                             "record is the validation data")
    holdout = _DEFAULT_HOLDOUT if args.holdout is None else args.holdout
    if args.validate is None and not (math.isfinite(holdout) and 0.0 < holdout < 1.0):
        raise ParameterError(f"--holdout {holdout} must be in (0, 1): orders are compared "
                             "on held-out data (or give --validate FILE)")
    band = None if args.band is None else check_band(args.band, "--band")
    for name in ("na", "nb", "nc", "delay"):
        low = 1 if name == "na" else 0
        bad = [v for v in getattr(args, name) or [] if v < low]
        if bad:
            raise ParameterError(f"--{name} {bad[0]} must be >= {low}")
    n_grid = (len(args.na) * len(args.nb or DEFAULT_NB) * len(args.nc)
               * len(args.delay or [0, 1]))
    if n_grid > 500:
        raise ParameterError(f"the grid has {n_grid} candidates; keep it to 500 or fewer")
    return {"holdout": None if args.validate is not None else holdout, "band": band,
            "decimate": _decimate_arg(args.decimate),
            "detrend": None if args.detrend == "none" else args.detrend}


def run(args: argparse.Namespace) -> int:
    from ehss.workflow import select_orders

    opts = _check_args(args)
    rec = load_record(args)
    val = load_validation(args, rec)
    validation = opts["holdout"] if val is None else (val.u, val.y)
    args.band_given = opts["band"] is not None
    from rich.console import Console

    console = Console(stderr=True)
    with report_warnings("order"), console.status("preparing the record") as status:
        progress = _Progress(status, tty=console.is_terminal)
        try:
            search = select_orders(
                rec.u, rec.y, fs=rec.fs, na=args.na, nb=args.nb, nc=args.nc,
                delay=args.delay, method=args.method, init=args.init, validation=validation,
                band_hz=opts["band"] or "input", detrend=opts["detrend"],
                decimate=opts["decimate"],
                initial=args.initial, criterion=args.criterion, progress=progress,
            )
        except DataError as exc:
            if args.delay is None and "to estimate a delay" in str(exc):
                raise DataError(f"{exc} with --delay") from None
            raise
    if not args.band_given:
        _say_input_band(args, opts, search.prepared)
    if search.delay_scan is not None:
        print(_delay_message(search), file=sys.stderr)
    command = identify_command(args, search)
    _print_table(search, rec, args)
    if not any(v is not None and v.accepted for v in search.verdicts):
        p = search.prepared
        rate = ("" if p.decimation == 1 or args.band is not None else
                f", or fit at a higher rate than {p.fs_model:g} Hz (--decimate N below "
                f"{p.decimation}: near its Nyquist frequency a sampled model of a loop "
                "with a dead time misses) or judge only the band of interest (--band LO "
                "HI)")
        print(f"no candidate meets the acceptance (the pick fails: "
              f"{'; '.join(search.verdicts[search.best_index].failed) or 'not validated'}); "
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
            "holdout": opts["holdout"],
            "method": args.method,
            "init": args.init,
            "criterion": args.criterion,
            "detrend": opts["detrend"],
            "decimation": p.decimation,
            "fs_data_hz": p.fs,
            "fs_model_hz": p.fs_model,
            "band_hz": None if opts["band"] is None else list(opts["band"]),
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

    def __init__(self, status, *, tty: bool) -> None:
        self.status, self.tty, self.done = status, tty, 0

    def __call__(self, line: str) -> None:
        self.done += 1
        text = f"fitted {self.done} candidates; last {line}"
        if self.tty:
            self.status.update(text)
        elif self.done % 20 == 0:
            print(f"ehss order: {text}", file=sys.stderr, flush=True)


def _say_input_band(args, opts: dict, prepared) -> None:
    """Say the band read from the input's spectrum, and carry it (with the decimation
    chosen before it was read) into the identify command."""
    from ehss.preprocess import EXCITATION_LEVEL_DB

    band = prepared.band_hz
    if band is None:
        return
    opts["band"] = args.band = band
    if prepared.decimation > 1 and opts["decimate"] == "auto":
        args.decimate = str(prepared.decimation)  # the band would change auto's factor
    print(f"band of interest read from the input's spectrum: {band[0]:.4g}-{band[1]:.4g} "
          f"Hz (where its power is within {EXCITATION_LEVEL_DB:g} dB of its peak, below "
          f"what the decimation leaves untouched; --band LO HI sets it)", file=sys.stderr)


def _delay_message(search) -> str:
    """What the record said about its delay and which delays were tried, at both rates."""
    from ehss.workflow import delay_text

    scan, p = search.delay_scan, search.prepared
    q = p.decimation

    def samples(d_model: int) -> str:  # model samples, and the record's when decimated
        if q == 1:
            return f"{d_model} samples"
        return f"{d_model} samples of the model at {p.fs_model:g} Hz ({d_model * q} at " \
               f"{p.fs:g} Hz)"

    tried = ", ".join(str(d) for d in sorted(set(search.delays)))
    nbs = sorted({r.nb for r in search.table})
    nb = f"nb {nbs[0]}-{nbs[-1]}" if len(nbs) > 1 else f"nb {nbs[0]}"
    if scan.supported:
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


def identify_command(args: argparse.Namespace, search) -> str:
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
        cmd += ["--holdout", repr(_DEFAULT_HOLDOUT if args.holdout is None else args.holdout)]
    cmd += ["--detrend", args.detrend, "--decimate", str(args.decimate).strip().lower()]
    if args.band is not None:
        cmd += ["--band", repr(args.band[0]), repr(args.band[1])]
    if args.initial != "estimate":
        cmd += ["--initial", args.initial]
    cmd += ["--out", "MODEL.json"]
    return shlex.join(cmd)


def _value(search, i: int, column: str) -> float:
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


def _print_table(search, rec, args) -> None:
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
