"""File arguments of the commands, and the one check of every output before the work.

A command declares each file argument with one of the argparse types below. Before the
command runs, :func:`check_paths` collects them from the parsed arguments and refuses,
in one line, any output that would lose a file (see :func:`ehss._files.check_outputs`):
an output that is an input, two outputs on one file, a table named ``.json`` or with an
unknown ending, a sidecar that is not the table's own, a missing or unwritable folder, a
symlink, FIFO, device or read-only file in the way.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path

__all__ = ["InputFile", "OutputFile", "OutputTable", "OutputFolder", "check_paths"]


class InputFile(str):
    """Argument type: a file the command reads (no output may be written onto it)."""

    __slots__ = ()


class OutputFile(str):
    """Argument type: one file the command writes (a model, a plot, a parameter file)."""

    __slots__ = ()


class OutputTable(str):
    """Argument type: a table the command writes, in the format named by its ending; a
    CSV table also writes its JSON sidecar (``run.csv`` → ``run.json``)."""

    __slots__ = ()


class OutputFolder(str):
    """Argument type: a folder the command writes files into (created if missing)."""

    __slots__ = ()


def _values(args: argparse.Namespace) -> list[object]:
    out: list[object] = []
    for value in vars(args).values():
        out.extend(value if isinstance(value, (list, tuple)) else [value])
    return out


def check_paths(args: argparse.Namespace) -> None:
    """Check every file argument of a parsed command line before the command runs.

    Outputs a command derives from its arguments (e.g. a second plot beside ``--plot``)
    are named by an optional ``derived_outputs(args) -> list[path]`` default of its parser.

    Raises
    ------
    DataError
        If an output would lose or replace a file, or cannot be written.
    """
    from ehss._files import check_folder, check_outputs, check_sidecar
    from ehss.errors import DataError
    from ehss.io.tables import table_files

    values = _values(args)
    inputs = [Path(v) for v in values if isinstance(v, InputFile)]
    outputs: list[Path | tuple[Path, str]] = []
    sidecars: list[tuple[Path, Path]] = []
    folders: list[Path] = []
    for v in values:
        if isinstance(v, OutputTable):
            table, *sides = table_files(v)
            outputs.append(table)
            for side in sides:
                outputs.append((side, f"the JSON sidecar of {str(table)!r}"))
                sidecars.append((side, table))
        elif isinstance(v, OutputFile):
            outputs.append(Path(v))
        elif isinstance(v, OutputFolder):
            folders.append(Path(v))
    derived: Callable[[argparse.Namespace], list] | None = getattr(args, "derived_outputs",
                                                                   None)
    if derived is not None:
        outputs.extend(Path(p) for p in derived(args))
    check_outputs(outputs, inputs=inputs)
    for side, table in sidecars:
        check_sidecar(side, table)
    for folder in folders:
        for src in inputs:
            if src.resolve() == folder.resolve():
                raise DataError(f"output folder {str(folder)!r} is the input "
                                f"{str(src)!r}")
        check_folder(folder)
