"""Write results atomically: tables at full precision in CSV or binary formats, and JSON."""

from __future__ import annotations

import contextlib
import json
import math
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ehss._files import SIDECAR_KEY, atomic_path, check_sidecar
from ehss.io.tables import (
    check_columns,
    table_files,
    table_format,
    write_csv_text,
    write_hdf5,
    write_mat,
    write_npz,
    write_parquet,
)

__all__ = ["write_csv", "write_table", "table_writers", "write_json", "to_jsonable"]


def write_csv(
    path: str | Path,
    columns: Mapping[str, Any],
    *,
    header_comment: str | None = None,
) -> Path:
    """Write equally long columns to a plain CSV file with one header row.

    Each value is the shortest text that reads back to the same float64, so a round trip
    through :func:`~ehss.io.read_columns` is exact. The file is written through
    :func:`~ehss._files.atomic_path`: it appears whole or not at all.

    Parameters
    ----------
    path : str or Path
        Output file.
    columns : mapping of str to array_like, each shape (n_rows,)
        Column names and values (real numbers).
    header_comment : str, optional
        Text written before the header, each line prefixed with ``"# "``;
        :func:`~ehss.io.read_columns` skips it.

    Returns
    -------
    Path
        The written file.

    Raises
    ------
    DataError
        If there are no columns, a column is not a real 1-D array, the lengths differ, or a
        name contains a comma, quote or line break.
    """
    arrays = check_columns(columns, "csv")
    header = ""
    if header_comment:
        header = "".join(f"# {line}".rstrip() + "\n" for line in header_comment.splitlines())
    with atomic_path(path) as tmp:
        write_csv_text(tmp, arrays, header)
    return Path(path)


def table_writers(
    path: str | Path,
    columns: Mapping[str, Any],
    metadata: Mapping[str, Any],
) -> dict[Path, Callable[[Path], None]]:
    """The files a table occupies, each with a function that writes it to a given path.

    Used by :func:`write_table`, and by callers that write several outputs together (each
    to a temporary file, renamed only when all succeeded). The format follows the ending
    of ``path`` (see :mod:`ehss.io.tables`): a CSV table has a JSON sidecar beside it
    (``run.csv`` → ``run.json``) marked as the table's, the binary formats hold the
    metadata inside.

    Raises
    ------
    DataError
        For a ``.json`` or unknown ending, bad columns (see :func:`write_csv`), or an
        existing file at the sidecar's name that is not this table's sidecar.
    TypeError
        If ``metadata`` has values with no JSON form.
    """
    path, *sides = table_files(path)
    fmt = table_format(path)
    arrays = check_columns(columns, fmt)
    doc = to_jsonable(dict(metadata))
    if sides:
        (side,) = sides
        check_sidecar(side, path)
        # the marker first, and never taken from the metadata (it names this table)
        sidecar_doc = {SIDECAR_KEY: path.name,
                       **{k: v for k, v in doc.items() if k != SIDECAR_KEY}}
        return {
            path: lambda tmp: write_csv_text(tmp, arrays),
            side: lambda tmp: _write_json_text(tmp, sidecar_doc),
        }
    text = json.dumps(doc, allow_nan=False)
    write = {"parquet": write_parquet, "hdf5": write_hdf5, "npz": write_npz,
             "mat": write_mat}[fmt]
    return {path: lambda tmp: write(tmp, arrays, text)}


def write_table(
    path: str | Path,
    columns: Mapping[str, Any],
    metadata: Mapping[str, Any],
) -> list[Path]:
    """Write a table and its metadata in the format named by the ending of ``path``.

    ``.csv`` (with a JSON sidecar), ``.parquet``, ``.h5``/``.hdf5``, ``.npz`` or ``.mat``;
    every format keeps float64 values exactly and carries the same metadata document
    (read it back with :func:`~ehss.io.read_metadata`). All files appear whole or not at
    all.

    Parameters
    ----------
    path : str or Path
        The table file.
    columns : mapping of str to array_like, each shape (n_rows,)
        Column names and values (real numbers).
    metadata : mapping
        Units, settings, seed, versions...: anything with a JSON form.

    Returns
    -------
    list of Path
        The written files (the table first).

    Raises
    ------
    DataError
        See :func:`table_writers`.
    """
    writers = table_writers(path, columns, metadata)
    with contextlib.ExitStack() as stack:
        for final, write in writers.items():
            write(stack.enter_context(atomic_path(final)))
    return list(writers)


def to_jsonable(obj: Any) -> Any:
    """Convert ``obj`` into plain JSON types.

    NumPy scalars and arrays become Python numbers and (nested) lists, paths become
    strings, tuples/sets become lists, and non-finite floats become ``None`` (JSON has no
    NaN or infinity).

    Raises
    ------
    TypeError
        For objects with no JSON form (complex numbers included).
    """
    if isinstance(obj, Mapping):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, set, frozenset)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        x = float(obj)
        return x if math.isfinite(x) else None
    if obj is None or isinstance(obj, str):
        return obj
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"cannot write {type(obj).__name__} {obj!r} to JSON")


def write_json(path: str | Path, obj: Any) -> Path:
    """Write ``obj`` as an indented JSON document, atomically.

    Floats keep full precision (Python's ``repr``); see :func:`to_jsonable` for the
    conversions applied.

    Returns
    -------
    Path
        The written file.
    """
    doc = to_jsonable(obj)
    with atomic_path(path) as tmp:
        _write_json_text(tmp, doc)
    return Path(path)


def _write_json_text(path: Path, doc: Any) -> None:
    path.write_text(json.dumps(doc, indent=2, allow_nan=False) + "\n", encoding="utf-8")
