"""Columns of a MATLAB ``.mat`` file (v5 through scipy, v7.3 as HDF5), and its ``Ts``."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ehss.errors import DataError
from ehss.io._columns import STORED_RATE_NAMES, Raw, pick, stored_rate
from ehss.io._hdf5 import is_hdf5, read_hdf5

__all__ = ["read_mat"]


def read_mat(path: Path, wanted: list[str] | None, optional: str | None) -> Raw:
    """Variables of a MATLAB file, struct fields by path (``"run1/u"``), and a rate
    stored as a scalar variable (``Ts``, ``fs``, ...): a
    :class:`~ehss.io._columns.Reader`. MATLAB v5 is read with :func:`scipy.io.loadmat`,
    v7.3 as HDF5.

    Raises
    ------
    DataError
        If the file is not a readable MATLAB file, or a column is unknown or not a
        vector.
    """
    try:
        with open(path, "rb") as fh:
            head = fh.read(1024)
    except OSError as exc:
        raise DataError(f"{str(path)!r}: cannot read: {exc.strerror or exc}") from None
    if is_hdf5(head):
        return read_hdf5(path, wanted, optional, matlab=True)
    import scipy.io

    try:
        content = scipy.io.loadmat(path, simplify_cells=True)
    except NotImplementedError:  # pragma: no cover - v7.3 without HDF5 signature
        return read_hdf5(path, wanted, optional, matlab=True)
    except Exception as exc:  # scipy raises many types on garbage
        raise DataError(f"{str(path)!r}: not a readable MATLAB file ({exc})") from None
    flat = _flatten({k: v for k, v in content.items() if not k.startswith("__")})
    scalars = {n: flat[n] for n in STORED_RATE_NAMES if n in flat and np.size(flat[n]) == 1}
    return Raw(pick(path, flat, wanted, optional), stored_rate=stored_rate(scalars))


def _flatten(obj: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Struct fields as ``"run1/u"`` beside the top-level variables."""
    out: dict[str, Any] = {}
    for key, value in obj.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            out.update(_flatten(value, prefix=f"{name}/"))
        else:
            out[name] = value
    return out
