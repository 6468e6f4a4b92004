"""Columns of a NumPy ``.npz`` archive, and a rate stored as a scalar entry."""

from __future__ import annotations

import zipfile
from pathlib import Path
from typing import BinaryIO

import numpy as np

from ehss.errors import DataError
from ehss.io._columns import STORED_RATE_NAMES, Raw, pick, select, stored_name, stored_rate

__all__ = ["read_npz"]

_UNREADABLE = (OSError, ValueError, zipfile.BadZipFile, EOFError)


def read_npz(path: Path, wanted: list[str] | None, optional: str | None) -> Raw:
    """Arrays of an ``.npz`` archive (no pickles) and a rate stored as a one-element
    entry (``fs``, ``Ts``, ...): a :class:`~ehss.io._columns.Reader`.

    Raises
    ------
    DataError
        If the file is not a readable archive, or a column is unknown or not a vector.
    """
    # The file is opened here so that it is closed even when numpy refuses it.
    try:
        with open(path, "rb") as fh, _archive(path, fh) as archive:
            files = list(archive.files)
            if wanted is None:
                flat = {k: archive[k] for k in files}
            else:
                names = select(path, files, wanted, optional)
                flat = {s: archive[s] for s in {stored_name(n, files) for n in names}}
            scalars = _scalars(archive)
    except _UNREADABLE as exc:
        raise DataError(f"{str(path)!r}: not a readable .npz file ({exc})") from None
    return Raw(pick(path, flat, wanted, optional), stored_rate=stored_rate(scalars))


def _archive(path: Path, fh: BinaryIO) -> np.lib.npyio.NpzFile:
    archive = np.load(fh, allow_pickle=False)
    if not isinstance(archive, np.lib.npyio.NpzFile):
        raise DataError(f"{str(path)!r}: not an .npz archive")
    return archive


def _scalars(archive: np.lib.npyio.NpzFile) -> dict[str, np.ndarray]:
    """One-element entries named like a sample rate or time."""
    found = {}
    for name in STORED_RATE_NAMES:
        try:
            value = archive[name] if name in archive.files else None
        except _UNREADABLE:
            continue  # an unreadable scalar is no rate; the columns were read
        if value is not None and value.size == 1:
            found[name] = value
    return found
