"""A recorded file as a live source: an ehss live recording, or any file that
:func:`ehss.read_columns` reads (CSV, MATLAB, HDF5, NumPy) with ``ref<k>``/``fb<k>``
columns."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np

import ehss
from ehss.errors import DataError, ParameterError
from ehss.live.layout import RecordLayout

__all__ = ["replay_record"]


def _is_live_recording(path: Path) -> bool:
    if path.suffix.lower() not in (".h5", ".hdf5"):
        return False
    try:
        with h5py.File(path, "r", libver="latest", swmr=True) as h:
            return "samples" in h and "fields" in h.attrs and "sample_index" in h
    except OSError:
        return False


def replay_record(
    path: str | Path, *, fields: tuple[str, ...] | None = None, fs: float | None = None,
    columns: tuple[str, ...] | None = None,
) -> tuple[RecordLayout, np.ndarray, float]:
    """Read a record to replay: ``(layout, samples, fs)``.

    Parameters
    ----------
    path : str or Path
        An ehss live recording (``ehss live --record``), or a data file.
    fields : tuple of str, optional
        Columns to take, in this order (default: every column of the file that is
        ``t``, ``ref<k>`` or ``fb<k>``).
    fs : float, optional
        Sample rate, Hz (default: from the recording or the ``t`` column).
    columns : tuple of str, optional
        Data files only: the file's column for each of ``fields`` (same length), so that
        a record with its own names (``time_s``, ``cmd``, ``pos``) replays as ``t``,
        ``ref1``, ``fb1`` (default: the fields' own names).

    Raises
    ------
    DataError
        Unreadable file, unknown column, no rate.
    """
    path = Path(path)
    if columns is not None:
        if fields is None or len(columns) != len(fields):
            raise ParameterError("columns needs fields of the same length")
        if _is_live_recording(path):
            raise ParameterError(f"{str(path)!r} is an ehss live recording: its fields "
                                 "keep their names (no FIELD=COLUMN)")
        return _renamed(path, tuple(fields), tuple(columns), fs)
    if _is_live_recording(path):
        with h5py.File(path, "r", libver="latest", swmr=True) as h:
            names = tuple(json.loads(h.attrs["fields"]))
            data = h["samples"][...]
            rate = float(h.attrs["fs"])
        if fields is not None:
            missing = [f for f in fields if f not in names]
            if missing:
                raise DataError(f"{str(path)!r}: no fields {missing}; it has {list(names)}")
            data = data[:, [names.index(f) for f in fields]]
            names = tuple(fields)
        layout = RecordLayout(names)
        return layout, np.ascontiguousarray(data), (rate if fs is None else float(fs))
    table = ehss.read_columns(path, None if fields is None else list(fields))
    if fields is None:
        fields = tuple(n for n in table.columns
                       if n == "t" or n.startswith("ref") or n.startswith("fb"))
    layout = RecordLayout(tuple(fields))
    data = np.column_stack([table[n] for n in layout.fields])
    rate = ehss.sample_rate(table, fs)
    return layout, data, float(rate)


def _renamed(path: Path, fields: tuple[str, ...], columns: tuple[str, ...],
             fs: float | None) -> tuple[RecordLayout, np.ndarray, float]:
    """A data file's ``columns`` replayed as ``fields``."""
    layout = RecordLayout(fields)
    time = columns[fields.index("t")] if "t" in fields else None
    table = ehss.read_columns(path, list(columns), time_column=time)
    data = np.column_stack([table[c] for c in columns])
    return layout, data, float(ehss.sample_rate(table, fs))
