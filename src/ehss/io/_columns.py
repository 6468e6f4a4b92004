"""What every record reader shares: the columns it found, how a request names a column,
and a sample rate stored beside the columns.

A reader (one module per format: ``_text``, ``_matlab``, ``_hdf5``, ``_npz``,
``_parquet``) opens its file once and returns a :class:`Raw`; ``readers`` checks the
columns and builds the public :class:`~ehss.io.readers.Table` from it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from ehss.errors import DataError

__all__ = [
    "Raw",
    "Reader",
    "RATE_NAMES_HZ",
    "PERIOD_NAMES_S",
    "STORED_RATE_NAMES",
    "TEXT_SUFFIXES",
    "stored_rate",
    "unknown_column",
    "column_number",
    "matrix_column",
    "stored_name",
    "column",
    "select",
    "as_vector",
    "pick",
]

#: File name endings read as text.
TEXT_SUFFIXES = (".csv", ".txt", ".dat", ".tsv")
#: Names of a scalar sample rate (Hz) a MATLAB, HDF5 or .npz file may store.
RATE_NAMES_HZ = ("fs", "Fs", "FS", "sample_rate", "sampling_rate", "srate")
#: Names of a scalar sample time (s): MATLAB's iddata calls it Ts.
PERIOD_NAMES_S = ("Ts", "ts", "dt", "sample_time")
#: Every name a stored rate or sample time may have, in the order they are looked for.
STORED_RATE_NAMES = RATE_NAMES_HZ + PERIOD_NAMES_S


@dataclass(frozen=True)
class Raw:
    """Columns as one reader found them, before the common checks (lengths, finiteness).

    Attributes
    ----------
    columns : dict of str to ndarray
        The columns, keyed as requested.
    labels : dict of str to str
        How a column is named in messages when that differs from ``column 'key'`` (a
        headerless text file's column is ``column 2``).
    stored_rate : (float, str) or None
        The sample rate stored beside the columns (see :func:`stored_rate`).
    """

    columns: dict[str, np.ndarray]
    labels: dict[str, str] = field(default_factory=dict)
    stored_rate: tuple[float, str] | None = None


class Reader(Protocol):
    """A format's reader: the columns of one file and its stored rate, from one opening.

    Parameters
    ----------
    path : Path
        The file (it exists and is a regular file).
    wanted : list of str or None
        The columns to read, each once: names (``"run1/u"`` in HDF5 and MATLAB
        structs), ``NAME:K`` for column K of a stored matrix, or in text files numbers
        counted from 1. None reads every numeric column.
    optional : str or None
        A column read as well when the file has it (the time column).

    Returns
    -------
    Raw
        The columns keyed by the requests as given, with their labels and the stored
        sample rate.

    Raises
    ------
    DataError
        If the file is not of the format, or a column is unknown or not numeric.
    """

    def __call__(self, path: Path, wanted: list[str] | None,
                 optional: str | None) -> Raw: ...


def stored_rate(found: Mapping[str, Any]) -> tuple[float, str] | None:
    """The sample rate (Hz) and where it came from, given the stored scalars ``found``.

    Parameters
    ----------
    found : mapping of str to scalar
        The one-element values a file stores under names of :data:`STORED_RATE_NAMES`.

    Returns
    -------
    (float, str) or None
        ``(rate_hz, "'Ts' = 0.001 s")`` from the first usable name; ``(nan, what)`` if
        the only stored values give no rate (``Ts = 0``), so that a message can say what
        the file holds; None if nothing is stored.
    """
    unusable = None
    for name in STORED_RATE_NAMES:
        if name not in found:
            continue
        try:
            value = float(np.asarray(found[name], dtype=np.float64).ravel()[0])
        except (TypeError, ValueError, IndexError):
            continue
        unit = "Hz" if name in RATE_NAMES_HZ else "s"
        if not (math.isfinite(value) and value > 0):
            unusable = unusable or (math.nan, f"{name!r} = {value:g} {unit}")
            continue
        rate = value if name in RATE_NAMES_HZ else 1.0 / value
        return rate, f"{name!r} = {value:g} {unit}"
    return unusable


def unknown_column(path: Path, name: str, available: list[str]) -> str:
    """The message for a column ``name`` the file does not have, listing ``available``."""
    shown = ", ".join(repr(a) for a in available[:30])
    if len(available) > 30:
        shown += f", ... ({len(available)} in all)"
    hint = ""
    if column_number(name) is not None and path.suffix.lower() not in TEXT_SUFFIXES:
        hint = (" (column numbers select columns of text files only; name the variable, "
                "or a column of a stored matrix as NAME:K, K counted from 1)")
    return f"{str(path)!r}: no column {name!r}; available: {shown or '(none)'}{hint}"


def column_number(spec: str) -> int | None:
    """The whole number written in ``spec`` (``"2"``, ``" 2 "``), or None."""
    text = spec.strip()
    return int(text) if text.isascii() and text.isdigit() else None


def matrix_column(spec: str, available: list[str]) -> tuple[str, int] | None:
    """``(NAME, K)`` if ``spec`` is ``NAME:K``, column K (from 1) of the stored matrix
    NAME (MATLAB's ``NAME(:, K)``), and NAME is stored; else None."""
    name, sep, k = spec.rpartition(":")
    number = column_number(k) if sep else None
    if number is None or number < 1 or name not in available:
        return None
    return name, number


def stored_name(spec: str, available: list[str]) -> str:
    """The stored variable that holds the column ``spec`` (itself, or NAME of NAME:K)."""
    if spec in available:
        return spec
    m = matrix_column(spec, available)
    return spec if m is None else m[0]


def as_vector(value: Any) -> np.ndarray | None:
    """A 1-D float64 array from a stored array, or None if it is not a numeric vector."""
    a = np.asarray(value)
    if a.dtype.kind not in "biuf" or a.ndim == 0:
        return None
    if a.ndim > 1:
        if sum(s != 1 for s in a.shape) > 1:
            return None
        a = a.reshape(-1)
    return a.astype(np.float64, copy=False)


def _vector_or_error(path: Path, name: str, value: Any) -> np.ndarray:
    a = as_vector(value)
    if a is None:
        shape = "x".join(str(s) for s in np.shape(value)) or "scalar"
        dtype = np.asarray(value).dtype
        what = "numeric" if dtype.kind in "biuf" else f"non-numeric ({dtype})"
        raise DataError(
            f"{str(path)!r}: {name!r} is a {shape} {what} array, not a numeric vector"
        )
    return a


def column(path: Path, spec: str, value: Any, available: list[str]) -> np.ndarray:
    """The column ``spec`` from its stored ``value``: a vector, or NAME:K of a matrix
    whose rows are the samples.

    Raises
    ------
    DataError
        If the value is not a numeric vector, or NAME is not a numeric matrix with a
        column K.
    """
    m = None if spec in available else matrix_column(spec, available)
    if m is None:
        return _vector_or_error(path, spec, value)
    name, k = m
    a = np.asarray(value)
    if a.dtype.kind not in "biuf" or a.ndim != 2:
        shape = "x".join(str(n) for n in a.shape) or "scalar"
        raise DataError(f"{str(path)!r}: {spec!r}: {name!r} is a {shape} array, not a "
                        "numeric matrix with one column per signal")
    if k > a.shape[1]:
        raise DataError(f"{str(path)!r}: {spec!r}: {name!r} has {a.shape[1]} columns "
                        f"({a.shape[0]} rows, one per sample)")
    return a[:, k - 1].astype(np.float64)


def select(path: Path, available: list[str], wanted: list[str],
           optional: str | None) -> list[str]:
    """The requests to read: ``wanted``, and first ``optional`` when the file has it.

    Raises
    ------
    DataError
        If a wanted column is neither stored nor NAME:K of a stored matrix.
    """
    for name in wanted:
        if name not in available and matrix_column(name, available) is None:
            raise DataError(unknown_column(path, name, available))
    names = list(wanted)
    if optional is not None and (optional in available
                                 or matrix_column(optional, available) is not None):
        names.insert(0, optional)
    return names


def pick(path: Path, flat: Mapping[str, Any], wanted: list[str] | None,
         optional: str | None) -> dict[str, np.ndarray]:
    """The requested columns of the stored values ``flat`` (every numeric vector when
    ``wanted`` is None)."""
    if wanted is None:
        vectors = {name: as_vector(value) for name, value in flat.items()}
        return {name: a for name, a in vectors.items() if a is not None}
    available = list(flat)
    return {n: column(path, n, flat[stored_name(n, available)], available)
            for n in select(path, available, wanted, optional)}
