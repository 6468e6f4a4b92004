"""``ehss compensate`` and ``ehss compensate-demo``: inverse-model feed-forward drives."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from ehss.errors import DataError

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "compensate",
        help="compute a compensated drive from an identified closed-loop model",
        description="Design the inverse (ZPETC or ZMETC, delay by preview) of an identified "
        "closed-loop model and apply it to a reference file. Writes columns t, reference, "
        "drive; replay with `ehss simulate --loop L --reference DRIVE.csv --column drive`.",
    )
    p.add_argument("model", metavar="MODEL.json", help="identified model (ArmaxModel JSON)")
    p.add_argument("reference", metavar="REFERENCE.csv", help="reference history file")
    p.add_argument("--out", required=True, metavar="DRIVE.csv", help="output CSV file")
    p.add_argument("--column", default="reference",
                   help="reference column name (default: %(default)s)")
    p.add_argument("--method", default="zpetc", choices=("zpetc", "zmetc"),
                   help="inverse design (default: %(default)s)")
    p.add_argument("--band", nargs=2, type=float, metavar=("LO", "HI"),
                   help="zero-phase band limit of the drive in Hz (default: none; required "
                   "for models identified behind known factors, e.g. the acceleration loop)")
    p.add_argument("--fs", type=float, metavar="HZ",
                   help="sample rate if the file has no time column t")
    p.add_argument("--ignore-offsets", action="store_true",
                   help="apply the inverse to the reference as it is, even if the model file "
                   "holds the operating point it was identified about (`offsets`, written by "
                   "`ehss identify`); by default drive = u0 + F (r - y0)")
    it = p.add_argument_group(
        "drive-file iteration",
        "Correct the drive of a previous run from what the rig did: "
        "u+ = u + L F (r - y), F the inverse of the model (re-identified from the run "
        "with --reidentify). A run file from `ehss simulate --reference DRIVE.csv --column "
        "drive` has the played drive in `reference` and the measurement in `output`.",
    )
    it.add_argument("--update", metavar="RUN.csv",
                    help="record of the previous run (played drive and measured output)")
    it.add_argument("--drive-column", default="reference",
                    help="played drive column in RUN.csv (default: %(default)s)")
    it.add_argument("--output-column", default="output",
                    help="measured output column in RUN.csv (default: %(default)s)")
    it.add_argument("--gain", type=float, default=1.0, metavar="L",
                    help="learning gain L in (0, 2) (default: %(default)s)")
    it.add_argument("--reidentify", action="store_true",
                    help="re-identify the loop from the run before inverting it")
    p.set_defaults(func=run)

    d = sub.add_parser(
        "compensate-demo",
        help="demonstrate inverse-model compensation on the simulated rig",
        description="Identify a closed loop on a random test, design its inverse, and "
        "compare tracking without and with compensation (random and earthquake-like "
        "references). Writes CSV/JSON figures and PNG plots to --out.",
    )
    d.add_argument("--loop", required=True, choices=("position", "acceleration"))
    d.add_argument("--out", default="compensation", metavar="DIR",
                   help="output folder (default: %(default)s)")
    d.add_argument("--seed", type=int, default=0, help="random seed (default: %(default)s)")
    d.add_argument("--duration", type=float, default=None, metavar="S",
                   help="length of each test record in seconds")
    d.add_argument("--method", default="zpetc", choices=("zpetc", "zmetc"))
    d.set_defaults(func=run_demo)


def run(args: argparse.Namespace) -> int:
    from ehss._files import check_writable
    from ehss._provenance import versions
    from ehss.cli._dataargs import write_outputs
    from ehss.compensation import compensate
    from ehss.identification.model import ArmaxModel
    from ehss.io import read_columns, sample_rate, write_csv, write_json

    check_writable(args.out)
    model = ArmaxModel.load_json(args.model)
    offsets = None if args.ignore_offsets else model.offsets
    table = read_columns(args.reference, [args.column])
    fs = sample_rate(table, args.fs)
    r = table[args.column]
    band = None if args.band is None else tuple(args.band)
    extra = {}
    if args.update is None:
        # the model maps deviations from the operating point (u0, y0) it was identified
        # about: y − y0 = G (u − u0), so the drive for r is u0 + G⁻¹ (r − y0)
        u0, y0 = offsets if offsets is not None else (0.0, 0.0)
        drive = u0 + compensate(model, r - y0, method=args.method, band_hz=band, fs=fs)
    else:  # corrections of the error r − y: the operating point cancels
        from ehss.compensation import update_drive

        run_table = read_columns(args.update, [args.drive_column, args.output_column])
        run_fs = sample_rate(run_table, args.fs)
        if abs(run_fs - fs) > 1e-9 * fs:
            raise DataError(f"{args.update!r} is sampled at {run_fs:g} Hz, the reference at "
                            f"{fs:g} Hz")
        step = update_drive(model, r, run_table[args.drive_column],
                            run_table[args.output_column], method=args.method, band_hz=band,
                            learning_gain=args.gain, reidentify=args.reidentify)
        drive = step.drive
        extra = {"update": {"run": str(args.update), "gain": args.gain,
                            "reidentify": args.reidentify,
                            "rms_error_of_run": step.rms_error}}
        print(f"previous run: RMS tracking error {step.rms_error:.6g}")
    t = table.time if table.time is not None else np.arange(r.size) / fs
    if not np.all(np.isfinite(drive)):
        raise DataError("the compensated drive is not finite (badly conditioned model?)")
    out = Path(args.out)
    sidecar = {
        "what": f"{args.method} inverse-model drive",
        "model": str(args.model),
        "reference": str(args.reference),
        "column": args.column,
        "fs_hz": fs,
        "band_hz": None if args.band is None else list(args.band),
        "offsets_applied": (None if offsets is None or args.update is not None
                            else {"input": offsets[0], "output": offsets[1]}),
        "units": "drive and reference in the units of the model's input",
        "versions": versions(),
        **extra,
    }
    write_outputs({out: lambda tmp: write_csv(tmp, {"t": t, "reference": r, "drive": drive}),
                   out.with_suffix(".json"): lambda tmp: write_json(tmp, sidecar)})
    return 0


def run_demo(args: argparse.Namespace) -> int:
    from ehss.compensation.demo import demonstrate, write_demo_report

    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise DataError(f"--out {str(out)!r} exists and is not a folder")
    kwargs = {} if args.duration is None else {"duration_s": args.duration}
    result = demonstrate(args.loop, seed=args.seed, method=args.method, **kwargs)
    out.mkdir(parents=True, exist_ok=True)
    paths = write_demo_report(result, out)
    print(result.summary())
    for p in paths:
        print(f"wrote {p}")
    return 0
