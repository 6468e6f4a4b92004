"""A recorded file as a live source: an ehss live recording, or any file that
:func:`ehss.read_columns` reads (CSV, MATLAB, HDF5, NumPy) with ``ref<k>``/``fb<k>``
columns."""

from __future__ import annotations

import json
import math
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
        names, data, rate = _recorded_samples(path)
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
        fields = _channel_fields(tuple(table.columns))
        if not any(f.startswith("ref") for f in fields):
            if {"reference", "output"} <= set(table.columns):  # written by ehss simulate
                names = ("t", "reference", "output") if "t" in table.columns else (
                    "reference", "output")
                return _renamed(path, ("t", "ref1", "fb1")[-len(names):], names, fs)
            _read_partners(path, tuple(table.columns))
            raise DataError(f"{str(path)!r} has no ref<k>/fb<k> columns (it has "
                            f"{list(table.columns)[:8]}): name the reference and feedback "
                            "as --fields t=TIME,ref1=COLUMN,fb1=COLUMN")
    layout = RecordLayout(tuple(fields))
    data = np.column_stack([table[n] for n in layout.fields])
    rate = ehss.sample_rate(table, fs)
    return layout, data, float(rate)


def _channel_fields(columns: tuple[str, ...]) -> tuple[str, ...]:
    """``t`` and every ``ref<k>``/``fb<k>`` pair among ``columns``, in their order."""
    pairs = {c[3:] for c in columns if c.startswith("ref")} & {
        c[2:] for c in columns if c.startswith("fb")}
    return tuple(c for c in columns if c == "t" or (c.startswith("ref") and c[3:] in pairs)
                 or (c.startswith("fb") and c[2:] in pairs))


def _read_partners(path: Path, columns: tuple[str, ...]) -> None:
    """Read by name the missing partner of each unpaired ``ref<k>``/``fb<k>`` column.

    Reading every column of a file keeps only the numeric ones; asked for by name, a
    partner that is there but holds text is refused as such (and one that is not there
    is named with the columns the file has)."""
    for c in columns:
        if c.startswith("ref"):
            partner = f"fb{c[3:]}"
        elif c.startswith("fb"):
            partner = f"ref{c[2:]}"
        else:
            continue
        if partner not in columns:
            ehss.read_columns(path, [partner])


def _open_complete(path: Path) -> h5py.File:
    """Open a recording to replay, refusing one cut short on disk.

    Opened for single-writer/multiple-reader access, HDF5 reads a truncated file's
    missing chunks as zeros without a word; opened plainly it checks the file's stored
    length. A recording whose writer was killed is still marked open for writing and
    only opens for SWMR reading: that one is read as it stands.
    """
    try:
        return h5py.File(path, "r")
    except OSError as exc:
        if "already open for write" not in str(exc):
            raise
    return h5py.File(path, "r", libver="latest", swmr=True)


def _recorded_samples(path: Path) -> tuple[tuple[str, ...], np.ndarray, float]:
    """The fields, samples and rate of an ehss live recording, each checked.

    Raises
    ------
    DataError
        If the file cannot be read, its ``fields`` attribute is not a JSON list of
        distinct names, its samples are not a real matrix with one column per field and
        at least one row, every one finite, or its rate is not a positive finite number.
    """
    where = str(path)
    try:
        with _open_complete(path) as h:
            fields_text, rate_attr, dset = h.attrs["fields"], h.attrs.get("fs"), h["samples"]
            if not isinstance(dset, h5py.Dataset) or dset.dtype.kind not in "fiu":
                raise DataError(f"{where!r}: its samples are not numbers "
                                f"(stored as {getattr(dset, 'dtype', 'a group')})")
            data = np.asarray(dset[...], dtype=np.float64)
    except (OSError, KeyError, TypeError) as exc:
        raise DataError(f"{where!r} is not a readable ehss live recording: {exc}") from None
    try:
        names = json.loads(fields_text)
    except (TypeError, ValueError):
        names = None
    if (not isinstance(names, list) or not names or len(set(map(str, names))) != len(names)
            or not all(isinstance(n, str) and n for n in names)):
        raise DataError(f"{where!r}: its 'fields' attribute must be a JSON list of distinct "
                        f"field names, got {str(fields_text)[:60]!r}")
    if data.ndim != 2 or data.shape[1] != len(names):
        raise DataError(f"{where!r}: its samples have shape {data.shape}, not (n, "
                        f"{len(names)}) for the fields {names}")
    if data.shape[0] == 0:
        raise DataError(f"{where!r} holds no samples: nothing to replay")
    _check_finite(where, names, data)
    try:
        rate = float(rate_attr)
    except (TypeError, ValueError):
        rate = math.nan
    if not (math.isfinite(rate) and rate > 0):
        raise DataError(f"{where!r}: its sample rate attribute 'fs' must be a positive "
                        f"number, got {rate_attr!r}")
    return tuple(names), np.ascontiguousarray(data), rate


def _check_finite(where: str, names: list[str], data: np.ndarray) -> None:
    """Refuse a recording with a NaN or infinite sample, naming the first: its field,
    its row of ``samples`` counted from 1, and its time when a ``t`` field holds it."""
    bad = ~np.isfinite(data)
    if not bad.any():
        return
    row, col = (int(k) for k in np.argwhere(bad)[0])
    t = data[row, names.index("t")] if "t" in names else math.nan
    at = f" (t = {float(t):g} s)" if math.isfinite(t) else ""
    raise DataError(f"{where!r}: field {names[col]!r} has a non-finite value "
                    f"({float(data[row, col])!r}) at sample row {row + 1}{at}")


def _renamed(path: Path, fields: tuple[str, ...], columns: tuple[str, ...],
             fs: float | None) -> tuple[RecordLayout, np.ndarray, float]:
    """A data file's ``columns`` replayed as ``fields``."""
    layout = RecordLayout(fields)
    time = columns[fields.index("t")] if "t" in fields else None
    table = ehss.read_columns(path, list(columns), time_column=time)
    data = np.column_stack([table[c] for c in columns])
    return layout, data, float(ehss.sample_rate(table, fs))
