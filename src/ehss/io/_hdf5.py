"""Columns of an HDF5 file (also a MATLAB v7.3 ``.mat``), and the rate stored beside them."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ehss.errors import DataError
from ehss.io._columns import (
    STORED_RATE_NAMES,
    Raw,
    column,
    select,
    stored_name,
    stored_rate,
)

__all__ = ["read_hdf5", "is_hdf5"]

_SIGNATURE = b"\x89HDF\r\n\x1a\n"
_MATLAB_NUMERIC = {
    None, "double", "single", "int8", "uint8", "int16", "uint16", "int32", "uint32",
    "int64", "uint64",
}


def is_hdf5(head: bytes) -> bool:
    """True if ``head`` (the first 1024 bytes of a file) starts an HDF5 file.

    The superblock sits at 0, 512, 1024, ... (MATLAB v7.3 puts a 512-byte header first).
    """
    return head.startswith(_SIGNATURE) or head[512:520] == _SIGNATURE


def read_hdf5(path: Path, wanted: list[str] | None, optional: str | None, *,
              matlab: bool = False) -> Raw:
    """Datasets of an HDF5 file by path (``"run1/u"``) and a rate stored as a scalar
    dataset or a root attribute: a :class:`~ehss.io._columns.Reader`.

    With ``matlab=True`` the file is a MATLAB v7.3 ``.mat``: arrays are stored
    column-major (transposed back here) and only numeric MATLAB classes are columns.

    Raises
    ------
    DataError
        If the file is not readable HDF5, or a column is unknown or not a vector.
    """
    import h5py

    try:
        fh = h5py.File(path, "r")
    except OSError as exc:
        raise DataError(f"{str(path)!r}: not a readable HDF5 file ({exc})") from None
    with fh:
        names: list[str] = []

        def visit(name: str, obj: Any) -> None:
            if isinstance(obj, h5py.Dataset) and not name.startswith("#"):
                names.append(name)

        fh.visititems(visit)
        if wanted is None:
            columns = {name: _load(fh[name], matlab) for name in names
                       if _is_column(fh[name], matlab)}
        else:
            chosen = select(path, names, wanted, optional)
            # a matrix whose columns are asked for is read once
            stored = {s: _load(fh[s], matlab) for s in {stored_name(n, names) for n in chosen}}
            columns = {n: column(path, n, stored[stored_name(n, names)], names)
                       for n in chosen}
        return Raw(columns, stored_rate=stored_rate(_scalars(fh)))


def _is_column(ds: Any, matlab: bool) -> bool:
    """A numeric vector (MATLAB's char and logical arrays carry another MATLAB_class)."""
    shape = ds.shape
    if ds.dtype.kind not in "biuf" or len(shape) < 1 or sum(s != 1 for s in shape) > 1:
        return False
    return not matlab or _matlab_class(ds) in _MATLAB_NUMERIC


def _matlab_class(ds: Any) -> str | None:
    value = ds.attrs.get("MATLAB_class")
    if value is None:
        return None
    return value.decode() if isinstance(value, bytes) else str(value)


def _load(ds: Any, matlab: bool) -> np.ndarray:
    a = ds[()]
    # MATLAB v7.3 stores column-major arrays, so an N-by-1 column arrives as shape (1, N);
    # transposing restores MATLAB's view (only matters for the error message on matrices).
    return a.T if matlab and np.ndim(a) >= 2 else a


def _scalars(fh: Any) -> dict[str, Any]:
    """One-element datasets and root attributes named like a sample rate or time."""
    import h5py

    found: dict[str, Any] = {}
    for name in STORED_RATE_NAMES:
        try:
            if name in fh and isinstance(fh[name], h5py.Dataset) and fh[name].size == 1:
                found[name] = fh[name][()]
            elif name in fh.attrs and np.size(fh.attrs[name]) == 1:
                found[name] = fh.attrs[name]
        except (OSError, TypeError, ValueError, KeyError):
            continue  # an unreadable scalar is no rate; the columns were read
    return found
