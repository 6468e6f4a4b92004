"""``ehss simulate``: run one closed-loop test on the simulated rig and save the record.

Outputs: a plain CSV (one header row; columns t, reference, output, then the internal
signals), a JSON sidecar next to it (units of every column, the full parameter set, loop,
signal kind and settings, seed, fs, versions) and optionally a PNG plot. All outputs are
written atomically and their folders are checked before the simulation starts.
"""

from __future__ import annotations

import argparse
import contextlib
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ehss.cli import add_command
from ehss.cli._outputs import InputFile, OutputFile, OutputTable
from ehss.cli._params import warn_if_unstable
from ehss.errors import ParameterError
from ehss.params import GRAVITY_M_S2, PRESETS, RigParams, load_params, params_to_dict, preset

if TYPE_CHECKING:
    from ehss.signals import Signal
    from ehss.simulation import SimulationResult

__all__ = ["register", "run", "seed_argument", "whole_number", "SIGNALS", "DEFAULT_AMPLITUDE",
           "DEFAULT_BAND_HZ"]

SIGNALS = ("step", "sine", "random", "sweep", "multisine")
#: Default size of a test per loop (SI units: m, m/s², N).
DEFAULT_AMPLITUDE = {"position": 1.0e-3, "acceleration": 0.05 * GRAVITY_M_S2, "force": 1000.0}
#: Default frequency band per loop: Table 2's working bands, from 1 Hz.
DEFAULT_BAND_HZ = {"position": (1.0, 20.0), "acceleration": (1.0, 50.0), "force": (1.0, 20.0)}
_LONG_RUN_S = 2.0  # show a progress indicator when the run should take longer than this
_EXPECTED_REAL_TIME_FACTOR = 400.0


def whole_number(text: str, *, lo: int, what: str) -> int:
    """``text`` as an option's whole number >= ``lo`` (``what`` ends the message)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if value < lo:
        raise argparse.ArgumentTypeError(f"{value} must be {what}")
    return value


def seed_argument(text: str) -> int:
    """The value of a ``--seed`` option: a whole number >= 0 (what numpy seeds with)."""
    return whole_number(text, lo=0, what="a whole number >= 0 (a seed)")


def register(sub: argparse._SubParsersAction) -> None:
    p = add_command(
        sub, "simulate",
        description="Simulate one closed-loop test of the rig: the nonlinear actuator "
        "channel with its digital controller, driven by a generated test signal or by a "
        "reference column read from a file. Writes CSV + JSON (units, parameters, seed) "
        "and optionally a plot.",
    )
    p.add_argument("--loop", required=True, choices=("position", "acceleration", "force"))
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--signal", choices=SIGNALS, help="generated reference signal")
    src.add_argument("--reference", metavar="FILE", type=InputFile,
                     help="read the reference from a file")
    p.add_argument("--column", default="reference",
                   help="reference column in --reference FILE (default: %(default)s)")
    p.add_argument("--time-column", default="t", metavar="COL",
                   help="time column of --reference FILE, used for the sample rate if "
                   "present; in seconds unless its name states a unit: 't [ms]', "
                   "'time_us' (default: %(default)s)")
    p.add_argument("--amplitude", type=float,
                   help="size in SI units of the loop (m, m/s², N); default per loop: "
                   + ", ".join(f"{k} {v:g}" for k, v in DEFAULT_AMPLITUDE.items()))
    p.add_argument("--freq", type=float, default=5.0, metavar="HZ",
                   help="sine frequency (default: %(default)s Hz)")
    p.add_argument("--band", type=float, nargs=2, metavar=("LO", "HI"),
                   help="band of random/sweep/multisine signals, Hz (default: the loop's "
                   "working band of Table 2)")
    p.add_argument("--offset", type=float, default=0.0,
                   help="constant added to the signal (e.g. a static force), SI units")
    p.add_argument("--duration", type=float, default=5.0, metavar="S",
                   help="length of a generated signal (default: %(default)s s)")
    p.add_argument("--fs", type=float, metavar="HZ",
                   help="control rate (default: the parameter set's, or the file's t column)")
    p.add_argument("--seed", type=seed_argument, default=0,
                   help="seed of the signal and the sensor noise, >= 0 (default: "
                   "%(default)s)")
    par = p.add_mutually_exclusive_group()
    par.add_argument("--params", metavar="FILE.toml", type=InputFile,
                     help="(partial) TOML parameter file")
    par.add_argument("--preset", choices=sorted(PRESETS), default="default",
                     help="named parameter set (default: %(default)s)")
    p.add_argument("--out", required=True, metavar="run.csv", type=OutputTable,
                   help="record to write: .csv (with a .json sidecar), .parquet, .h5, .npz "
                   "or .mat")
    p.add_argument("--plot", metavar="run.png", type=OutputFile, help="also draw the record")
    p.set_defaults(func=run)


def _generate(args: argparse.Namespace, fs: float) -> Signal:
    """The generated reference as an ``ehss.signals.Signal``."""
    from ehss import signals

    loop = args.loop
    amp = DEFAULT_AMPLITUDE[loop] if args.amplitude is None else args.amplitude
    lo, hi = DEFAULT_BAND_HZ[loop] if args.band is None else args.band
    common = {"duration_s": args.duration, "fs": fs}
    if args.signal == "step":
        return signals.step(amp, start_s=min(0.1, 0.1 * args.duration), offset=args.offset,
                            **common)
    if args.signal == "sine":
        return signals.sine(amp, args.freq, offset=args.offset, **common)
    if args.signal == "random":
        return signals.band_limited_random(band_hz=(lo, hi), peak=amp, seed=args.seed,
                                           offset=args.offset, **common)
    if args.signal == "sweep":
        return signals.swept_sine(amp, f0_hz=lo, f1_hz=hi, offset=args.offset, **common)
    return signals.multisine(band_hz=(lo, hi), peak=amp, seed=args.seed, offset=args.offset,
                             **common)


def _load_params(args: argparse.Namespace) -> RigParams:
    return load_params(args.params) if args.params else preset(args.preset)


def run(args: argparse.Namespace) -> int:
    from ehss.cli._dataargs import write_outputs
    from ehss.io import read_columns, sample_rate, table_writers

    out = Path(args.out)
    if args.duration is not None and not args.duration > 0:
        raise ParameterError(f"--duration {args.duration!r} must be > 0")

    params = _load_params(args)
    if args.reference:
        table = read_columns(args.reference, [args.column], time_column=args.time_column)
        fs = sample_rate(table, args.fs)
        values = np.asarray(table[args.column], dtype=np.float64)
        kind = "file"
        settings: dict[str, Any] = {"path": str(args.reference), "column": args.column,
                                    "time_column": table.time_column}
    else:
        fs = params.timing.control_rate_hz if args.fs is None else args.fs
        sig = _generate(args, fs)
        values = np.asarray(sig.values, dtype=np.float64)
        kind = getattr(sig, "kind", args.signal)
        settings = dict(getattr(sig, "settings", {}) or {})

    from ehss.compensation.checks import check_rig
    from ehss.simulation import simulate, with_control_rate

    checked = with_control_rate(params, fs)  # fs must divide the internal rate: fail before work
    # the one check of what a loop plays, the one `ehss compensate --loop` applies to a drive
    check_rig(values, args.loop, checked, fs, step=kind == "step")
    source = f"--params {args.params}" if args.params else f"--preset {args.preset}"
    warn_if_unstable("simulate", params, args.loop, source)

    expected_s = values.size / fs / _EXPECTED_REAL_TIME_FACTOR
    with _progress(expected_s, f"simulating {values.size / fs:.4g} s of the {args.loop} loop"):
        result = simulate(args.loop, values, params=params, fs=fs, seed=args.seed)

    meta = _metadata(result, kind, settings)
    writers = table_writers(out, result.to_columns(), meta)
    if args.plot:
        from ehss.plots import plot_simulation

        # the temporary file keeps the plot's suffix, which picks the format
        def draw(tmp: Path) -> None:
            plot_simulation(result, tmp)

        writers[Path(args.plot)] = draw
    write_outputs(writers)
    hits = result.limits_hit
    if hits:
        import sys

        note = ", ".join(f"{k} {v:.1%}" for k, v in hits.items())
        print(f"ehss simulate: warning: the test hit a limit ({note})", file=sys.stderr)
    return 0


def _metadata(result: SimulationResult, kind: str, settings: dict[str, Any]) -> dict[str, Any]:
    from ehss._provenance import timestamp, versions

    return {
        "loop": result.loop,
        "fs_hz": result.fs,
        "seed": result.seed,
        "n_samples": int(result.t.size),
        "signal": {"kind": kind, "settings": settings},
        "columns": list(result.to_columns()),
        "units": result.units,
        "limits_hit": result.limits_hit,
        "params": params_to_dict(result.params),
        "versions": versions(),
        "created": timestamp(),
    }


@contextlib.contextmanager
def _progress(expected_s: float, text: str) -> Iterator[None]:
    """A rich status line on stderr for runs expected to take longer than ~2 s."""
    if expected_s < _LONG_RUN_S:
        yield
        return
    from rich.console import Console

    with Console(stderr=True).status(text):
        yield
