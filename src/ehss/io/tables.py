"""Table file formats: CSV with a JSON sidecar, Parquet, HDF5, NumPy ``.npz`` and MATLAB.

A table is a set of named, equally long float64 columns with a metadata document (units,
settings, seed, versions). The format follows the file name's ending:

========================  ===================================  ============================
ending                    columns                              metadata
========================  ===================================  ============================
``.csv``                  text, shortest exact float64 text    JSON sidecar ``<name>.json``
``.parquet``              float64 columns                      key ``ehss`` of the file's
                                                               key-value metadata
``.h5`` / ``.hdf5``       float64 datasets at the root         attribute ``ehss`` of the
                                                               root group
``.npz``                  float64 arrays                       entry ``ehss_metadata``
``.mat`` (MATLAB v5)      double vectors                       char variable
                                                               ``ehss_metadata``
========================  ===================================  ============================

Every format stores float64 exactly, so reading a table back gives the same bits. The
metadata is the same JSON document in each.
"""

from __future__ import annotations

import contextlib
import io
import json
import re
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ehss._files import SIDECAR_KEY, sidecar_path
from ehss.errors import DataError

if TYPE_CHECKING:
    import polars as pl

__all__ = [
    "TABLE_SUFFIXES",
    "METADATA_KEY",
    "table_format",
    "table_files",
    "check_columns",
    "write_csv_text",
    "write_parquet",
    "write_hdf5",
    "write_npz",
    "write_mat",
    "read_metadata",
]

#: Table formats by file name ending.
TABLE_SUFFIXES = {
    ".csv": "csv",
    ".parquet": "parquet",
    ".h5": "hdf5",
    ".hdf5": "hdf5",
    ".npz": "npz",
    ".mat": "mat",
}
#: Name under which binary formats hold the metadata document (JSON text).
METADATA_KEY = "ehss_metadata"
_PARQUET_KEY = "ehss"
_HDF5_ATTR = "ehss"
_MATLAB_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,62}")


def table_format(path: str | Path) -> str:
    """The table format named by the ending of ``path``: csv, parquet, hdf5, npz or mat.

    Raises
    ------
    DataError
        For ``.json`` (the table and its sidecar would be one file) and unknown endings.
    """
    suffix = Path(path).suffix.lower()
    if suffix == ".json":
        raise DataError(f"cannot write a table to {str(path)!r}: a .json name is kept for "
                        "the table's JSON sidecar; use .csv, .parquet, .h5, .npz or .mat")
    try:
        return TABLE_SUFFIXES[suffix]
    except KeyError:
        raise DataError(f"cannot write a table to {str(path)!r}: unknown ending "
                        f"{suffix or '(none)'!r}; use one of "
                        f"{', '.join(TABLE_SUFFIXES)}") from None


def table_files(path: str | Path) -> list[Path]:
    """The files a table occupies: the table, then its JSON sidecar if it is a CSV.

    Raises
    ------
    DataError
        See :func:`table_format`.
    """
    path = Path(path)
    return [path, sidecar_path(path)] if table_format(path) == "csv" else [path]


def check_columns(columns: Mapping[str, Any], fmt: str = "csv") -> dict[str, np.ndarray]:
    """Equally long real 1-D columns as float64 arrays, with names the format can hold.

    Raises
    ------
    DataError
        If there are no columns, a column is not a real 1-D array, the lengths differ, or
        a name is empty, holds a comma, quote or line break (CSV), a slash (HDF5, npz),
        is not a MATLAB variable name (mat), or is the metadata's own name.
    """
    if not columns:
        raise DataError("write: no columns to write")
    arrays: dict[str, np.ndarray] = {}
    for name, values in columns.items():
        if not isinstance(name, str) or not name or any(c in name for c in ',"\n\r'):
            raise DataError(f"write: column name {name!r} must be a non-empty string "
                            "without commas, quotes or line breaks")
        if fmt in ("hdf5", "npz", "parquet") and ("/" in name or name == METADATA_KEY):
            raise DataError(f"write: column name {name!r} cannot be stored in {fmt} "
                            f"(no '/', and {METADATA_KEY!r} holds the metadata)")
        if fmt == "mat" and (not _MATLAB_NAME.fullmatch(name) or name == METADATA_KEY):
            raise DataError(f"write: column name {name!r} is not a MATLAB variable name "
                            "(a letter, then letters, digits or _, at most 63)")
        a = np.asarray(values)
        if a.ndim != 1:
            raise DataError(f"write: column {name!r} has shape {a.shape}, expected 1-D")
        if a.dtype.kind not in "biuf":
            raise DataError(f"write: column {name!r} has dtype {a.dtype}, expected real")
        arrays[name] = np.ascontiguousarray(a, dtype=np.float64)
    lengths = {n: a.size for n, a in arrays.items()}
    if len(set(lengths.values())) > 1:
        raise DataError(f"write: columns have unequal lengths {lengths}")
    return arrays


@contextlib.contextmanager
def _os_errors() -> Iterator[None]:
    """Report a failed polars write (a full disk, say) as the OSError it is."""
    import polars as pl

    try:
        yield
    except pl.exceptions.PolarsError as exc:
        text = str(exc).strip().splitlines()
        raise OSError(text[-1] if text else type(exc).__name__) from None


def _frame(arrays: Mapping[str, np.ndarray]) -> pl.DataFrame:
    import polars as pl

    # float64 numpy arrays become polars columns without a copy
    return pl.DataFrame({name: pl.Series(name, a) for name, a in arrays.items()})


def write_csv_text(path: Path, arrays: Mapping[str, np.ndarray], header: str = "") -> None:
    """Write float64 columns as CSV text (one header row) to ``path`` (not atomic).

    Each value is written by polars with the fewest digits that read back to the same
    float64, so a round trip is exact; ``header`` is written first.
    """
    with open(path, "wb") as fh:
        if header:
            fh.write(header.encode("utf-8"))
        with _os_errors():
            _frame(arrays).write_csv(fh, include_header=True, line_terminator="\n")


def write_parquet(path: Path, arrays: Mapping[str, np.ndarray], metadata_json: str) -> None:
    """Write float64 columns as Parquet (uncompressed) with the metadata document."""
    with _os_errors():
        _frame(arrays).write_parquet(path, compression="uncompressed", statistics=False,
                                     metadata={_PARQUET_KEY: metadata_json})


def write_hdf5(path: Path, arrays: Mapping[str, np.ndarray], metadata_json: str) -> None:
    """Write float64 columns as root datasets of an HDF5 file, metadata as an attribute.

    The file is built in memory and then written by Python, so a failed write (a full
    disk) is an ordinary OSError rather than an error inside the HDF5 library, which can
    leave it unable to close the file.
    """
    import h5py

    buffer = io.BytesIO()
    with h5py.File(buffer, "w", track_order=True) as fh:
        fh.attrs[_HDF5_ATTR] = metadata_json
        for name, a in arrays.items():
            fh.create_dataset(name, data=a)
    with open(path, "wb") as out:
        out.write(buffer.getbuffer())


def write_npz(path: Path, arrays: Mapping[str, np.ndarray], metadata_json: str) -> None:
    """Write float64 columns to an uncompressed ``.npz``, metadata as a text entry."""
    with open(path, "wb") as fh:  # a file object: np.savez would append .npz to a name
        entries = {**arrays, METADATA_KEY: np.array(metadata_json)}
        np.savez(fh, allow_pickle=False, **entries)


def write_mat(path: Path, arrays: Mapping[str, np.ndarray], metadata_json: str) -> None:
    """Write float64 columns as MATLAB v5 column vectors, metadata as a char variable."""
    import scipy.io

    content: dict[str, Any] = {name: a for name, a in arrays.items()}
    content[METADATA_KEY] = metadata_json
    with open(path, "wb") as fh:
        scipy.io.savemat(fh, content, oned_as="column", do_compression=False)


def read_metadata(path: str | Path) -> dict[str, Any] | None:
    """The metadata document of a table written by ehss, or None if it has none.

    For a CSV table this is its JSON sidecar (without the sidecar marker); for the binary
    formats the document stored inside the file.
    """
    path = Path(path)
    fmt = table_format(path)
    text: str | None = None
    if fmt == "csv":
        side = sidecar_path(path)
        if not side.is_file():
            return None
        doc = json.loads(side.read_text(encoding="utf-8"))
        if not isinstance(doc, dict) or doc.get(SIDECAR_KEY) != path.name:
            return None
        return {k: v for k, v in doc.items() if k != SIDECAR_KEY}
    if fmt == "parquet":
        import polars as pl

        text = pl.read_parquet_metadata(path).get(_PARQUET_KEY)
    elif fmt == "hdf5":
        import h5py

        with h5py.File(path, "r") as fh:
            value = fh.attrs.get(_HDF5_ATTR)
        text = value.decode() if isinstance(value, bytes) else value
    elif fmt == "npz":
        with np.load(path, allow_pickle=False) as archive:
            text = str(archive[METADATA_KEY]) if METADATA_KEY in archive.files else None
    else:
        import scipy.io

        content = scipy.io.loadmat(path, variable_names=[METADATA_KEY], simplify_cells=True)
        text = content.get(METADATA_KEY)
    return None if text is None else json.loads(text)
