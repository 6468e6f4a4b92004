"""Pieces shared by the subcommands that read an input/output record from a file."""

from __future__ import annotations

import argparse
import contextlib
import math
import re
import sys
import warnings
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ehss._checks import check_band
from ehss.cli._outputs import InputFile
from ehss.errors import ParameterError

__all__ = [
    "add_record_arguments",
    "add_rate_arguments",
    "Record",
    "load_record",
    "load_validation",
    "int_list",
    "check_outputs",
    "write_outputs",
    "report_warnings",
]


#: How columns are chosen, shown in --help.
COLUMN_HELP = ("by header name or, in text files, by number counted from 1 (1 is the first "
               "column, as in MATLAB and awk); text files without a header row, such as "
               "DaISy .dat records, are read by number; in .mat/.h5/.npz files NAME:K is "
               "column K of the stored matrix NAME (MATLAB's NAME(:, K))")


def add_record_arguments(p: argparse.ArgumentParser) -> None:
    """DATA, --input, --output, --fs, --time-column."""
    p.add_argument("data", metavar="DATA", type=InputFile,
                   help="record file: text (.csv/.txt/.dat/.tsv; comma, semicolon, tab or "
                   "whitespace separated; header row optional), .mat (v5 or v7.3), "
                   ".h5/.hdf5, .npz or .parquet")
    p.add_argument("--input", required=True, metavar="COL",
                   help="input column (e.g. the loop's reference), " + COLUMN_HELP)
    p.add_argument("--output", required=True, metavar="COL",
                   help="output column (the measured controlled variable): name, or number "
                   "from 1")
    add_rate_arguments(p, "time column (name, or number from 1)")


def add_rate_arguments(p: argparse._ActionsContainer, time_column: str) -> None:
    """--fs and --time-column: the sample rate, given or read from the time column
    (``time_column`` says which column that is)."""
    p.add_argument("--fs", type=float, metavar="HZ",
                   help="sample rate in Hz (needed when the file has no time column)")
    p.add_argument("--time-column", default="t", metavar="COL",
                   help=f"{time_column}, used for the sample rate if present; in seconds "
                   "unless its name states a unit: 't [ms]', 'time_us' (default: "
                   "%(default)s)")


@dataclass(frozen=True)
class Record:
    """An input/output record read from a file."""

    path: Path
    t: np.ndarray
    u: np.ndarray
    y: np.ndarray
    fs: float


def load_record(args: argparse.Namespace) -> Record:
    """Read ``--input``/``--output`` from DATA, find the sample rate and check the scale.

    Raises
    ------
    ParameterError
        If --input, --output and --time-column do not name three different columns.
    DataError
        If the file cannot be read (see :func:`ehss.io.read_columns`), the sample rate
        cannot be found (:func:`ehss.io.sample_rate`), or a column is constant or beyond
        the magnitudes ehss computes with (:func:`ehss._checks.check_scale`); the message
        names the file and the column.
    """
    from ehss._checks import check_scale
    from ehss.io import read_columns, sample_rate

    if args.input == args.output:
        raise ParameterError(f"--input and --output are the same column {args.input!r}")
    table = read_columns(args.data, [args.input, args.output], time_column=args.time_column)
    where = f"{str(table.path)!r}"
    if table.label(args.input) == table.label(args.output):
        raise ParameterError(f"--input {args.input} and --output {args.output} are the same "
                             f"{table.label(args.input)} of {where}")
    if table.time_column is not None:
        for option, key in (("--input", args.input), ("--output", args.output)):
            if table.label(table.time_column) == table.label(key):
                raise ParameterError(f"--time-column {table.time_column} and {option} {key} "
                                     f"are the same {table.label(key)} of {where}")
    fs = sample_rate(table, args.fs)
    u, y = table[args.input], table[args.output]
    check_scale(u, f"{where}: {table.label(args.input)} (--input)")
    check_scale(y, f"{where}: {table.label(args.output)} (--output)")
    t = table.time if table.time is not None else np.arange(u.size) / fs
    return Record(path=Path(args.data), t=t, u=u, y=y, fs=fs)


def int_list(text: str) -> list[int]:
    """Parse ``"2,3,4"``, ``"2-6"`` or ``"2:6"`` (inclusive ranges) into integers."""
    out: list[int] = []
    for part in text.split(","):
        part = part.strip()
        if not part:
            continue
        sep = "-" if "-" in part[1:] else (":" if ":" in part else None)
        try:
            if sep is None:
                out.append(int(part))
            else:
                i = part.index(sep, 1) if sep == "-" else part.index(sep)
                lo, hi = int(part[:i]), int(part[i + 1 :])
                if hi < lo:
                    raise ValueError
                out.extend(range(lo, hi + 1))
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"{text!r} is not a list of integers such as 2,3,4 or 2-6"
            ) from None
    if not out:
        raise argparse.ArgumentTypeError(f"{text!r} holds no integers")
    return list(dict.fromkeys(out))


def load_validation(args: argparse.Namespace, rec: Record) -> Record | None:
    """The ``--validate FILE`` record, read with DATA's column options, or None.

    Raises
    ------
    ParameterError
        If it is sampled at another rate than DATA, or ``--band`` reaches above fs/2.
    """
    band = getattr(args, "band", None)
    if band is not None:
        check_band(band, "--band", fs=rec.fs)
    if args.validate is None:
        return None
    val = load_record(argparse.Namespace(**{**vars(args), "data": args.validate}))
    if not math.isclose(val.fs, rec.fs, rel_tol=1e-6):
        raise ParameterError(f"--validate {args.validate} is sampled at {val.fs:g} Hz, "
                             f"DATA at {rec.fs:g} Hz: they must match")
    return val


def check_outputs(*paths: str | Path | None, inputs: Sequence[str | Path] = ()) -> list[Path]:
    """Check before any work that every output can be written without losing a file.

    The command line already checks every declared file argument before a command runs
    (:func:`ehss.cli._outputs.check_paths`); this is for outputs known only later.
    """
    from ehss._files import check_outputs as check

    return check([p for p in paths if p is not None], inputs=inputs)


def write_outputs(writers: dict[Path, Callable[[Path], None]]) -> None:
    """Write every output to a temporary file first; rename them only when all succeeded.

    ``writers`` maps each final path to a function writing the content to a given path
    (for a table and its sidecar: :func:`ehss.io.table_writers`).
    """
    from ehss._files import atomic_path

    with contextlib.ExitStack() as stack:
        for final, write in writers.items():
            tmp = stack.enter_context(atomic_path(final))
            write(tmp)


@contextlib.contextmanager
def report_warnings(command: str) -> Iterator[None]:
    """Show EhssWarnings raised inside as one ``warning:`` line each on stderr.

    Warnings that differ only in their numbers (the same check failing for many
    candidate models) are shown once, with how many times they came.
    """
    from ehss.errors import EhssWarning

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", EhssWarning)
        yield
    first: dict[str, str] = {}
    count: dict[str, int] = {}
    for w in caught:
        if issubclass(w.category, EhssWarning):
            text = str(w.message)
            key = re.sub(r"[-+]?\d[\d.]*(e[-+]?\d+)?", "#", text)
            first.setdefault(key, text)
            count[key] = count.get(key, 0) + 1
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    for key, text in first.items():
        times = f" ({count[key]} times, the first shown)" if count[key] > 1 else ""
        print(f"ehss {command}: warning: {text}{times}", file=sys.stderr)
