"""An archive of records: which files and groups hold them, and how to read a channel.

A *record* is one test: a table file (CSV, MATLAB, NumPy ``.npz``, Parquet or HDF5 with
its columns at the root), one group of an HDF5 file holding several tests (one group
per test, its columns inside), or an ``ehss live`` recording (``/samples`` with the
field names in the root attribute ``fields``). A *channel* is one input/output pair of
a record: the reference (model input) and the feedback (model output) of one actuator.

:func:`discover` turns globs into records without reading their samples;
:func:`read_channel` reads one channel's samples and sample rate; :func:`record_time`
finds when a record was made.
"""

from __future__ import annotations

import datetime as _dt
import glob
import hashlib
import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ehss.errors import DataError
from ehss.io import SUPPORTED_SUFFIXES, read_columns, read_metadata, sample_rate

__all__ = [
    "Record",
    "Channel",
    "discover",
    "read_channel",
    "channel_pairs",
    "record_columns",
    "record_time",
    "TIME_KEYS",
]

#: Metadata keys (of a table's metadata document, an HDF5 group's or file's attributes)
#: read as the record's time, ISO 8601, in this order; else the file's modification time.
TIME_KEYS = ("recorded_at", "record_time", "start_time", "timestamp", "created")

_HDF5 = (".h5", ".hdf5")
_PAIR = re.compile(r"^(ref|fb)(.*)$")


@dataclass(frozen=True)
class Record:
    """One record of an archive.

    Attributes
    ----------
    path : str
        The file.
    group : str
        The HDF5 group holding the record's columns ("" for the whole file).
    kind : {"table", "hdf5-group", "live"}
    """

    path: str
    group: str = ""
    kind: str = "table"

    @property
    def name(self) -> str:
        """``path`` or ``path::group``, as the record is named in results."""
        return f"{self.path}::{self.group}" if self.group else self.path

    @property
    def key(self) -> str:
        """A file-safe unique key: the name's tail and a hash of the whole name."""
        slug = re.sub(r"[^A-Za-z0-9_.-]+", "_", Path(self.path).name + "_" + self.group)
        digest = hashlib.sha256(self.name.encode("utf-8")).hexdigest()[:10]
        return f"{slug.strip('_.')[:60]}-{digest}"


@dataclass(frozen=True)
class Channel:
    """One input/output pair: ``name`` in the results, ``input`` and ``output`` columns."""

    name: str
    input: str
    output: str


def _is_live(h: Any) -> bool:
    return "samples" in h and "fields" in h.attrs


def _hdf5_records(path: str) -> list[Record]:
    import h5py

    try:
        with h5py.File(path, "r") as h:
            if _is_live(h):
                return [Record(path, "", "live")]
            if any(isinstance(v, h5py.Dataset) for v in h.values()):
                return [Record(path, "", "table")]
            groups = sorted(k for k, v in h.items() if isinstance(v, h5py.Group))
    except OSError:
        return [Record(path)]  # unreadable: reading it records the error
    return [Record(path, g, "hdf5-group") for g in groups]


def discover(patterns: list[str], *, root: str | Path | None = None) -> list[Record]:
    """The records the glob ``patterns`` name (``**`` recurses), sorted by name.

    A pattern without wildcards names one file, which need not exist: a missing file
    becomes a record whose reading fails, so that the results say so. Patterns are
    relative to ``root`` when given (a manifest's folder).

    Raises
    ------
    DataError
        If a pattern with wildcards matches no file.
    """
    out: list[Record] = []
    for pattern in patterns:
        full = str(Path(root) / pattern) if root is not None else str(pattern)
        if glob.has_magic(full):
            matches = sorted(p for p in glob.glob(full, recursive=True)
                             if Path(p).is_file() and Path(p).suffix.lower()
                             in SUPPORTED_SUFFIXES)
            if not matches:
                raise DataError(f"no record file matches {pattern!r} (accepted: "
                                f"{', '.join(SUPPORTED_SUFFIXES)})")
        else:
            matches = [full]
        for m in matches:
            h5 = Path(m).suffix.lower() in _HDF5 and Path(m).is_file()
            out.extend(_hdf5_records(m) if h5 else [Record(m)])
    unique = {r.name: r for r in out}
    return sorted(unique.values(), key=lambda r: r.name)


def channel_pairs(columns: list[str]) -> list[Channel]:
    """Channels a record's column names imply: ``ref<k>``/``fb<k>`` pairs (as ``ehss
    live`` names them), else ``reference``/``output`` (as ``ehss simulate`` writes)."""
    refs: dict[str, str] = {}
    fbs: dict[str, str] = {}
    for c in columns:
        m = _PAIR.match(c)
        if m:
            (refs if m.group(1) == "ref" else fbs)[m.group(2)] = c
    both = [k for k in refs if k in fbs]
    if both:
        return [Channel(k or "1", refs[k], fbs[k]) for k in sorted(both, key=_natural)]
    if "reference" in columns and "output" in columns:
        return [Channel("1", "reference", "output")]
    raise DataError(f"cannot tell the channels from the columns {columns}: name them in "
                    "the manifest ([[channels]] name, input, output)")


def _natural(text: str) -> tuple:
    return tuple(int(p) if p.isdigit() else p for p in re.split(r"(\d+)", text))


def _live_columns(path: str) -> tuple[list[str], float]:
    import h5py

    try:
        with h5py.File(path, "r", libver="latest", swmr=True) as h:
            return json.loads(h.attrs["fields"]), float(h.attrs["fs"])
    except (OSError, KeyError, ValueError) as exc:
        raise DataError(f"{path!r} is not a readable ehss live recording: {exc}") from None


def record_columns(record: Record) -> list[str]:
    """The names of a record's columns (reads the file's layout, not its samples)."""
    if record.kind == "live":
        return _live_columns(record.path)[0]
    if record.kind == "hdf5-group":
        import h5py

        with h5py.File(record.path, "r") as h:
            return list(h[record.group].keys())
    return list(read_columns(record.path, None, time_column=None).columns)


def read_channel(record: Record, channel: Channel, *, time_column: str | None = "t",
                 fs: float | None = None) -> tuple[np.ndarray, np.ndarray, float]:
    """Input, output and sample rate (Hz) of one channel of a record.

    The sample rate comes from ``fs`` when given, else the record's time column or the
    rate it stores (:func:`ehss.io.sample_rate`; a live recording's ``fs`` attribute).

    Raises
    ------
    DataError
        If the file is missing or unreadable, or lacks a column (the message lists the
        columns it has).
    """
    if record.kind == "live":
        return _read_live(record, channel, fs)
    prefix = f"{record.group}/" if record.group else ""
    cols = [prefix + channel.input, prefix + channel.output]
    tcol = prefix + time_column if time_column else None
    table = read_columns(record.path, cols, time_column=tcol)
    return table[cols[0]], table[cols[1]], sample_rate(table, fs)


def _read_live(record: Record, channel: Channel, fs: float | None
               ) -> tuple[np.ndarray, np.ndarray, float]:
    import h5py

    fields, rate = _live_columns(record.path)
    for c in (channel.input, channel.output):
        if c not in fields:
            raise DataError(f"{record.path!r}: no column {c!r} in the live recording "
                            f"(fields: {', '.join(fields)})")
    i, o = fields.index(channel.input), fields.index(channel.output)
    with h5py.File(record.path, "r", libver="latest", swmr=True) as h:
        samples = h["samples"][...]
    if fs is not None and abs(fs - rate) > 1e-2 * fs:
        raise DataError(f"{record.path!r}: the recording's rate is {rate:g} Hz, the "
                        f"manifest's fs {fs:g} Hz; drop fs or make them agree")
    return (np.ascontiguousarray(samples[:, i], dtype=np.float64),
            np.ascontiguousarray(samples[:, o], dtype=np.float64), rate)


def _parse_time(value: Any) -> _dt.datetime | None:
    if isinstance(value, bytes):
        value = value.decode()
    if not isinstance(value, str):
        return None
    try:
        t = _dt.datetime.fromisoformat(value.strip())
    except ValueError:
        return None
    if t.tzinfo is None:
        t = t.replace(tzinfo=_dt.UTC)
    return t.astimezone(_dt.UTC)


def _metadata(record: Record) -> dict[str, Any]:
    if record.kind in ("live", "hdf5-group") or Path(record.path).suffix.lower() in _HDF5:
        import h5py

        with h5py.File(record.path, "r") as h:
            node = h[record.group] if record.group else h
            attrs = dict(node.attrs)
        if record.kind == "table":
            attrs.update(read_metadata(record.path) or {})
        return attrs
    try:
        return read_metadata(record.path) or {}
    except (OSError, ValueError):
        return {}


def record_time(record: Record) -> tuple[_dt.datetime, str]:
    """When the record was made (UTC) and where that came from: the first of
    :data:`TIME_KEYS` in its metadata, else the file's modification time."""
    meta = _metadata(record)
    for key in TIME_KEYS:
        t = _parse_time(meta.get(key))
        if t is not None:
            return t, f"metadata {key!r}"
    mtime = Path(record.path).stat().st_mtime
    return _dt.datetime.fromtimestamp(mtime, tz=_dt.UTC), "file modification time"
