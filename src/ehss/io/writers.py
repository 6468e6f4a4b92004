"""Write results atomically: plain CSV columns at full precision, and JSON documents."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ehss._files import atomic_path
from ehss.errors import DataError

__all__ = ["write_csv", "write_json", "to_jsonable"]


def write_csv(
    path: str | Path,
    columns: Mapping[str, Any],
    *,
    header_comment: str | None = None,
) -> Path:
    """Write equally long columns to a plain CSV file with one header row.

    Values are written with ``repr`` (the shortest text that reads back to the same
    float64), so a round trip through :func:`~ehss.io.read_columns` is exact. The file is
    written through :func:`~ehss._files.atomic_path`: it appears whole or not at all.

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
    if not columns:
        raise DataError("write_csv: no columns to write")
    arrays: dict[str, np.ndarray] = {}
    for name, values in columns.items():
        if not isinstance(name, str) or not name or any(c in name for c in ',"\n\r'):
            raise DataError(f"write_csv: column name {name!r} must be a non-empty string "
                            "without commas, quotes or line breaks")
        a = np.asarray(values)
        if a.ndim != 1:
            raise DataError(f"write_csv: column {name!r} has shape {a.shape}, expected 1-D")
        if a.dtype.kind not in "biuf":
            raise DataError(f"write_csv: column {name!r} has dtype {a.dtype}, expected real")
        arrays[name] = a.astype(np.float64, copy=False)
    lengths = {n: a.size for n, a in arrays.items()}
    if len(set(lengths.values())) > 1:
        raise DataError(f"write_csv: columns have unequal lengths {lengths}")
    lines: list[str] = []
    if header_comment:
        lines.extend(f"# {line}".rstrip() for line in header_comment.splitlines())
    lines.append(",".join(arrays))
    rows = zip(*(a.tolist() for a in arrays.values()), strict=True)
    lines.extend(",".join(map(repr, row)) for row in rows)
    text = "\n".join(lines) + "\n"
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


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
    text = json.dumps(to_jsonable(obj), indent=2, allow_nan=False) + "\n"
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)
