"""``ehss compensate`` and ``ehss compensate-demo``: checked inverse-model drive files."""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path
from typing import Any

import numpy as np

from ehss._checks import check_band
from ehss.cli import add_command
from ehss.cli._dataargs import add_rate_arguments
from ehss.cli._options import add_options, build_options
from ehss.cli._outputs import InputFile, OutputFolder, OutputTable
from ehss.cli._simulate import seed_argument
from ehss.errors import DataError, ParameterError

__all__ = ["register"]

_DRIVE_LOOPS = ("position", "acceleration", "force", "valve")


def register(sub: argparse._SubParsersAction) -> None:
    from ehss.compensation import DEFAULT_MAX_GAIN, DEFAULT_MIN_GAIN, DriveLimits, UpdateOptions
    from ehss.params import PRESETS

    p = add_command(
        sub, "compensate",
        description="Invert an identified closed-loop model inside the band it was validated "
        "over (exact stable inversion by default) and apply it to a reference file, or "
        "correct the drive of a previous run. Outside that band the drive is the reference "
        "itself. A model identified from a decimated record (the `ehss identify` default "
        "for oversampled records) is applied at the reference's rate, an integer multiple "
        "of the model's. The drive is checked before anything is "
        "written: its gain against the reference's and, with a parameter set or limits, the "
        "rig's limits. Writes columns t, reference, drive (and a JSON sidecar with the "
        "checks and the per-run log); replay with `ehss simulate --loop L --reference "
        "DRIVE.csv --column drive`.",
    )
    p.add_argument("model", metavar="MODEL.json", type=InputFile,
                   help="identified model (ArmaxModel JSON)")
    p.add_argument("reference", metavar="REFERENCE.csv", type=InputFile,
                   help="reference history file")
    p.add_argument("--out", required=True, metavar="DRIVE.csv", type=OutputTable,
                   help="drive table: .csv (with a .json sidecar), .parquet, .h5, .npz or "
                   ".mat")
    p.add_argument("--column", default="reference",
                   help="reference column name (default: %(default)s)")
    p.add_argument("--method", default="stable", choices=("stable", "zpetc", "zmetc", "frf"),
                   help="inverse: exact stable inversion (default), ZPETC, ZMETC, or, to "
                   "correct a run (--update), the measured frequency response of that run")
    p.add_argument("--band", nargs=2, type=float, metavar=("LO", "HI"),
                   help="band limit of the inverse and of every update, Hz (default: the "
                   "band the model was validated over, `band_hz` in its file)")
    add_rate_arguments(p, "time column of the reference (and of the --update run)")
    p.add_argument("--fade", type=float, metavar="S",
                   help="fade the reference in and out over S seconds (raised cosine) when it "
                   "does not start or end at rest")
    p.add_argument("--ignore-offsets", action="store_true",
                   help="apply the inverse to the reference as it is, even if the model file "
                   "holds the operating point it was identified about (`offsets`, written by "
                   "`ehss identify`); by default drive = u0 + F (r - y0)")
    ck = p.add_argument_group(
        "drive checks",
        "A drive whose RMS or peak exceeds --max-gain times the reference's, whose RMS is "
        "under --min-gain times the reference's, or that breaks the rig's limits (with "
        "--loop: those `ehss simulate` checks, on the default preset unless --params or "
        "--preset), is an error (exit 2) and nothing is written.",
    )
    ck.add_argument("--max-gain", type=float, default=DEFAULT_MAX_GAIN, metavar="G",
                    help="bound on the drive/reference RMS and peak ratios (default: "
                    "%(default)s)")
    ck.add_argument("--min-gain", type=float, default=DEFAULT_MIN_GAIN, metavar="G",
                    help="lower bound on the drive/reference RMS ratio: a drive far smaller "
                    "than its reference means a model whose gain is wrong (default: "
                    "%(default).3g)")
    ck.add_argument("--force", action="store_true",
                    help="write the drive even if it fails the checks (recorded in the "
                    "sidecar)")
    ck.add_argument("--loop", choices=_DRIVE_LOOPS,
                    help="loop the drive is played into, whose limits it must respect "
                    "(of --params or --preset; default preset otherwise, as `ehss "
                    "simulate`)")
    par = ck.add_mutually_exclusive_group()
    par.add_argument("--params", metavar="FILE.toml", type=InputFile,
                     help="(partial) TOML parameter file")
    par.add_argument("--preset", choices=sorted(PRESETS), help="named parameter set")
    ck.add_argument("--max-stroke", type=float, metavar="X",
                    help="bound on |drive| (e.g. m of stroke)")
    ck.add_argument("--max-command", type=float, metavar="V",
                    help="bound on |drive| for a valve-command drive (V)")
    add_options(ck, DriveLimits)
    it = p.add_argument_group(
        "drive-file iteration",
        "Correct the drive of a previous run from what the rig did: u+ = u + L Q F (r - y), "
        "Q the band limit, F the model's inverse (or, with --method frf, the inverse of the "
        "run's H1 estimate, weighted by its coherence). A run file from `ehss simulate "
        "--reference DRIVE.csv --column drive` has the played drive in `reference` and the "
        "measurement in `output`. With --previous (the drive file that was played), the run "
        "is compared with the one before: when its error grew the update is refused and the "
        "gain halved; after three refusals the iteration stops and the best drive is "
        "written back.",
    )
    it.add_argument("--update", metavar="RUN.csv", type=InputFile,
                    help="record of the previous run (played drive and measured output)")
    it.add_argument("--previous", metavar="DRIVE.csv", type=InputFile,
                    help="the drive file (written by this command) that was played")
    it.add_argument("--drive-column", default="reference",
                    help="played drive column in RUN.csv (default: %(default)s)")
    it.add_argument("--output-column", default="output",
                    help="measured output column in RUN.csv (default: %(default)s)")
    add_options(it, UpdateOptions)
    p.set_defaults(func=run)

    d = add_command(
        sub, "compensate-demo",
        description="Identify a closed loop on a random test, invert it in its working band "
        "(stable inversion by default), iterate the drive file, and compare tracking "
        "without and with compensation (random and earthquake-like references). Writes "
        "CSV/JSON figures and PNG plots to --out.",
    )
    d.add_argument("--loop", required=True, choices=("position", "acceleration"))
    d.add_argument("--out", default=OutputFolder("compensation"), metavar="DIR",
                   type=OutputFolder,
                   help="output folder (default: %(default)s)")
    d.add_argument("--seed", type=seed_argument, default=0,
                   help="random seed, >= 0 (default: %(default)s)")
    d.add_argument("--duration", type=float, default=None, metavar="S",
                   help="length of each test record in seconds")
    d.add_argument("--method", default="stable", choices=("stable", "zpetc", "zmetc"))
    d.set_defaults(func=run_demo)


def _limits(args: argparse.Namespace) -> Any:
    from ehss.compensation import DriveLimits

    if args.max_stroke is not None and args.max_command is not None:
        raise ParameterError("give --max-stroke or --max-command, not both (both bound |drive|)")
    bound = args.max_stroke if args.max_stroke is not None else args.max_command
    if bound is None and args.max_velocity is None and args.max_acceleration is None:
        return None
    return build_options(args, DriveLimits, max_abs=bound)


def _rig(args: argparse.Namespace) -> tuple[str | None, Any]:
    """The loop the drive is played into and its rig: as ``ehss simulate`` plays it (the
    default preset unless --params or --preset), so a drive written here is one it
    plays."""
    from ehss.params import load_params, preset

    given = args.params is not None or args.preset is not None
    if given and args.loop is None:
        raise ParameterError("--params/--preset need --loop: the loop the drive is played into")
    if args.loop is None:
        return None, None
    if args.params is not None:
        return args.loop, load_params(args.params)
    return args.loop, preset(args.preset or "default")


def _band(args: argparse.Namespace, model: Any) -> tuple[float, float]:
    if args.band is not None:
        return check_band(args.band, "--band")
    if model.band_hz is None:
        raise ParameterError(
            f"model {args.model!r} carries no validated band (band_hz): pass --band LO HI, "
            "e.g. the band where its validation's coherence was high; without a band limit "
            "the inverse amplifies everything the model never saw")
    return model.band_hz


def _check_flags(args: argparse.Namespace) -> None:
    if args.update is None:
        for flag, given in (("--previous", args.previous is not None),
                            ("--gain", args.gain is not None), ("--reidentify", args.reidentify)):
            if given:
                raise ParameterError(f"{flag} belongs to a drive-file iteration: give "
                                     "--update RUN.csv")
        if args.method == "frf":
            raise ParameterError(
                "--method frf corrects a measured run: give --update RUN.csv (play the "
                "reference itself, or a model-based drive, first)")
    if args.reidentify and args.method == "frf":
        raise ParameterError("--reidentify re-identifies the model of a model-based update; "
                             "--method frf uses no model")


def _one_shot(args: argparse.Namespace, model: Any, r: np.ndarray, fs: float,
              band: tuple[float, float], checks: dict[str, Any]) -> Any:
    """The library's compensation, kept even when a check fails (:func:`run` decides)."""
    from ehss.compensation import compensation

    return compensation(model, r, fs=fs, method=args.method, band_hz=band,
                        offsets=None if args.ignore_offsets else "model", fade_s=args.fade,
                        force=True, **checks)


def _iterated(args: argparse.Namespace, model: Any, r: np.ndarray, fs: float,
              band: tuple[float, float], checks: dict[str, Any]) -> tuple[Any, dict, dict]:
    """A drive-file iteration step: the library's, kept even when a check fails."""
    from ehss.compensation import UpdateOptions, corrected_drive, model_offsets
    from ehss.compensation.rates import rate_factor
    from ehss.io import read_columns, sample_rate

    rate_factor(fs, model.dt)  # the model's rate, or a decimated one: DataError if not
    run_table = read_columns(args.update, [args.drive_column, args.output_column],
                             time_column=args.time_column)
    run_fs = sample_rate(run_table, args.fs)
    if abs(run_fs - fs) > 1e-9 * fs:
        raise DataError(f"{args.update!r} is sampled at {run_fs:g} Hz, the reference at "
                        f"{fs:g} Hz")
    u = np.asarray(run_table[args.drive_column], dtype=float)
    y = np.asarray(run_table[args.output_column], dtype=float)
    if u.size != r.size or y.size != r.size:
        raise DataError(f"{args.update!r} has {u.size} samples, the reference {r.size}")
    offsets = None if args.ignore_offsets else "model"
    state: Any = None
    log: list[dict[str, Any]] = []
    if args.previous is not None:
        state, log = _previous(args.previous, u, model_offsets(model, offsets)[0], fs)
    method = "frf" if args.method == "frf" else "model"
    options = build_options(args, UpdateOptions, method=method, band_hz=band,
                            inverse_method="stable" if method == "frf" else args.method)
    result, step = corrected_drive(model, r, u, y, fs=fs, offsets=offsets, fade_s=args.fade,
                                   force=True, checks=checks, state=state, options=options)
    entry = {"run": str(args.update), **step.record.to_dict(), "accepted": step.accepted,
             "gain_next": step.gain, "decision": step.message}
    log = [*log, entry]
    print(f"run {len(log)}: RMS error {step.record.rms_error:.6g} "
          f"({step.record.nrmse_percent:.3g} %), lag {step.record.lag_samples:.2f} samples; "
          f"{step.message}")
    st = step.state
    extra = {"iteration": {
        "log": log, "gain": step.gain, "base_rms_error": st.base_rms_error,
        "halvings": st.halvings, "stopped": step.stopped, "method": method,
        "reidentify": bool(args.reidentify), "previous": args.previous,
    }, "update": {"run": str(args.update), "gain": step.gain,
                  "rms_error_of_run": step.record.rms_error}}
    if step.stopped:
        return result, {}, extra
    u0 = result.offsets[0]
    return result, {"base_drive": u0 + st.base_drive, "correction": st.correction}, extra


def run(args: argparse.Namespace) -> int:
    from ehss._provenance import versions
    from ehss.cli._dataargs import write_outputs
    from ehss.identification.model import ArmaxModel
    from ehss.io import read_columns, sample_rate, table_writers

    _check_flags(args)
    model = ArmaxModel.load_json(args.model)
    band = _band(args, model)
    loop, params = _rig(args)
    checks = {"max_gain": args.max_gain, "min_gain": args.min_gain, "limits": _limits(args),
              "loop": loop, "params": params}
    table = read_columns(args.reference, [args.column], time_column=args.time_column)
    fs = sample_rate(table, args.fs)
    r = np.asarray(table[args.column], dtype=float)
    if args.update is None:
        result = _one_shot(args, model, r, fs, band, checks)
        columns: dict[str, Any] = {}
        extra: dict[str, Any] = {"iteration": {"log": [], "gain": None}}
    else:
        result, columns, extra = _iterated(args, model, r, fs, band, checks)
    if result.failed_check is not None and not args.force:
        hint = ("--max-gain/--min-gain or --force" if "reference's (bound" in
                result.failed_check else "--force")
        raise ParameterError(f"{result.failed_check} (nothing written; {hint} to override)")
    sidecar = _sidecar(args, model, result, band, checks, versions())
    out = Path(args.out)
    t = table.time if table.time is not None else np.arange(r.size) / fs
    cols = {"t": t, "reference": result.reference, "drive": result.drive, **columns}
    write_outputs(table_writers(out, cols, {**sidecar, **extra}))
    _say(args, model, result, band, loop, out)
    return 0


def _sidecar(args: argparse.Namespace, model: Any, result: Any, band: tuple[float, float],
             checks: dict[str, Any], versions: dict[str, Any]) -> dict[str, Any]:
    q, limits = result.decimation, checks["limits"]
    u0, y0 = result.offsets
    return {
        "what": f"{args.method} inverse-model drive",
        "model": str(args.model),
        "reference": str(args.reference),
        "column": args.column,
        "fs_hz": result.fs,
        "model_fs_hz": 1.0 / model.dt,
        "resampled": (None if q == 1 else
                      f"model at fs/{q}: the inverse ran at its rate between polyphase "
                      "resampling (ehss.compensation.rates)"),
        "outside_band": ("reference: outside band_hz the drive is the reference itself"
                         if args.update is None else
                         "the update's correction is limited to band_hz (Q-filter)"),
        "method": args.method,
        "band_hz": list(band),
        "band_from": "--band" if args.band is not None else "model band_hz",
        "fade_s": args.fade,
        "offsets_applied": (None if args.ignore_offsets or model.offsets is None
                            else {"input": u0, "output": y0}),
        "checks": {"forced": bool(args.force),
                   "failed": result.failed_check,
                   "figures": None if result.check is None else result.check.to_dict(),
                   "limits": None if limits is None else dataclasses.asdict(limits),
                   "loop": checks["loop"],
                   "rig": None if checks["params"] is None else checks["params"].name},
        "warnings": list(result.warnings),
        "units": "drive and reference in the units of the model's input and output",
        "versions": versions,
    }


def _say(args: argparse.Namespace, model: Any, result: Any, band: tuple[float, float],
         loop: str | None, out: Path) -> None:
    """Format the result: warnings on stderr, one summary line on stdout."""
    import sys

    for text in result.warnings:
        print(f"ehss compensate: warning: {text}", file=sys.stderr)
    if result.failed_check is not None:
        print(f"ehss compensate: warning: --force: {result.failed_check}")
    if loop is None:
        print("ehss compensate: note: the drive was not checked against a rig's limits; "
              "give --loop L (with --params/--preset, the default preset otherwise) to "
              "check it as `ehss simulate` will", file=sys.stderr)
    q, chk = result.decimation, result.check
    rate = "" if q == 1 else f" (model at fs/{q}, {1.0 / model.dt:g} Hz)"
    gains = ("" if chk is None else
             f"; drive/reference gain rms {chk.rms_gain:.3g}, peak {chk.peak_gain:.3g}")
    print(f"{out}: {result.drive.size} samples at {result.fs:g} Hz{rate}, {args.method} "
          f"inverse within {band[0]:g}-{band[1]:g} Hz{gains}")


def _previous(path: str, played: np.ndarray, u0: float, fs: float) -> tuple[Any, list]:
    """Iteration state of a drive file written by this command, checked against the run
    (its samples, and its rate when it has a time column)."""
    from ehss.io import read_columns, read_metadata, sample_rate

    table = read_columns(path)
    if table.time_column is not None:
        rate = sample_rate(table)
        if abs(rate - fs) > 1e-9 * fs:
            raise DataError(f"{path!r} is sampled at {rate:g} Hz, the run at {fs:g} Hz: "
                            "not the drive that was played")
    if "drive" not in table.columns:
        raise DataError(f"{path!r} has no column 'drive': not a drive file of this command")
    drive = np.asarray(table["drive"], dtype=float)
    if drive.size != played.size or not np.allclose(drive, played, rtol=1e-9,
                                                     atol=1e-12 * np.max(np.abs(drive))):
        raise DataError(f"the run did not play {path!r}: its drive differs from the file's")
    # the metadata travels with the table: the JSON sidecar of a CSV, inside the others
    try:
        doc = read_metadata(path)
    except (OSError, ValueError) as exc:
        raise DataError(f"cannot read the metadata of the previous drive file {path!r}: "
                        f"{exc}") from None
    it = doc.get("iteration") if isinstance(doc, dict) else None
    if not isinstance(it, dict) or not isinstance(it.get("log", []), list):
        raise DataError(f"the previous drive file {path!r} carries no iteration record "
                        "(field 'iteration' with its 'log'): not a drive file of this command")
    log = list(it.get("log") or [])
    if "base_drive" not in table.columns:
        return None, log  # a one-shot drive (or the best one handed back): nothing to compare
    return _state(path, table, it, u0), log


def _state(path: str, table: Any, it: dict[str, Any], u0: float) -> Any:
    """The iteration state a previous drive file records; DataError naming the file and the
    field when it is missing or edited beyond what an update leaves."""
    from ehss.compensation import IterationState

    if "correction" not in table.columns:
        raise DataError(f"the previous drive file {path!r} has 'base_drive' but no "
                        "'correction' column")
    for key in ("gain", "base_rms_error"):
        if key not in it:
            raise DataError(f"the previous drive file {path!r}: field 'iteration.{key}' is "
                            "missing")
    try:
        return IterationState(base_drive=np.asarray(table["base_drive"], float) - u0,
                              correction=np.asarray(table["correction"], float),
                              gain=it["gain"], base_rms_error=it["base_rms_error"],
                              halvings=it.get("halvings", 0))
    except (TypeError, ParameterError, DataError) as exc:
        raise DataError(f"the previous drive file {path!r}: iteration {exc}") from None


def run_demo(args: argparse.Namespace) -> int:
    from ehss.experiments.compensation_demo import demonstrate, write_demo_report

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
