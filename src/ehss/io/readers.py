"""Read measured or simulated records: named float64 columns from CSV, MATLAB, HDF5, NPZ.

Every problem with a file becomes a :class:`~ehss.errors.DataError` that names the file,
the column and, where it applies, the first bad row counted as a user counts rows in a
spreadsheet: data row 1 is the first row after the header.
"""

from __future__ import annotations

import csv
import math
import re
import zipfile
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ehss._checks import SAMPLE_RATE_RANGE_HZ
from ehss.errors import DataError

__all__ = ["Table", "read_columns", "sample_rate", "time_unit", "SUPPORTED_SUFFIXES"]

#: Units of time a time column's name may state, in seconds.
TIME_UNITS_S = {
    "s": 1.0, "sec": 1.0, "secs": 1.0, "second": 1.0, "seconds": 1.0,
    "ms": 1e-3, "msec": 1e-3, "millisecond": 1e-3, "milliseconds": 1e-3,
    "us": 1e-6, "µs": 1e-6, "μs": 1e-6, "usec": 1e-6, "microseconds": 1e-6,
    "ns": 1e-9, "min": 60.0, "h": 3600.0,
}
# A unit at the end of a column name: "t [ms]", "time (s)", "time_ms", "t ms", "t/ms".
_BRACKETED_UNIT = re.compile(r"[\[(]\s*([^\[\]()]+?)\s*[\])]\s*$")
_SUFFIX_UNIT = re.compile(r"[_\s/]([A-Za-zµμ]+)\s*$")


def time_unit(name: str) -> tuple[str, float]:
    """The unit a time column's name states, and its length in seconds.

    ``"t [ms]"``, ``"time (ms)"``, ``"time_ms"``, ``"t ms"`` and ``"t/ms"`` state
    milliseconds; a name stating no unit (``"t"``, ``"time"``) is taken as seconds.

    Raises
    ------
    DataError
        If the name states a unit in brackets that is not one of time (``"t [samples]"``).
    """
    m = _BRACKETED_UNIT.search(name)
    if m:
        unit = m.group(1)
        if unit.lower() not in TIME_UNITS_S and unit not in TIME_UNITS_S:
            raise DataError(f"time column {name!r} is in {unit!r}, not a unit of time "
                            "(s, ms, us, ns, min, h); pass the sample rate with --fs "
                            "instead")
    else:
        m = _SUFFIX_UNIT.search(name)
        unit = m.group(1) if m and (m.group(1) in TIME_UNITS_S
                                    or m.group(1).lower() in TIME_UNITS_S) else "s"
    return unit, TIME_UNITS_S.get(unit, TIME_UNITS_S.get(unit.lower(), 1.0))

#: File name endings understood by :func:`read_columns`.
SUPPORTED_SUFFIXES = (
    ".csv", ".txt", ".dat", ".tsv", ".mat", ".h5", ".hdf5", ".npz", ".parquet",
)

_HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


@dataclass(frozen=True, kw_only=True, eq=False)
class Table(Mapping[str, np.ndarray]):
    """Named, equally long float64 columns read from one file.

    Behaves as a read-only mapping ``name -> ndarray, shape (n_rows,)``; asking for an
    unknown column raises :class:`DataError` listing the available ones.

    Attributes
    ----------
    path : Path
        The file the columns were read from.
    columns : dict of str to ndarray
        The columns, each float64, contiguous, finite and of length ``n_rows``.
    time_column : str or None
        Name of the time column if the file had one, else None. Its values are in
        seconds unless the name states another unit (:func:`time_unit`: ``"t [ms]"``);
        :attr:`time` gives them in seconds.
    labels : dict of str to str
        How each column is named in messages when that is not ``column 'key'``: a column
        of a headerless text file is ``column 2``; one chosen by number from a file with
        a header is ``column 'u'`` (its name).
    stored_rate : (float, str) or None
        A sample rate the file stores beside its columns (Hz, and where it was found:
        ``"'Ts' = 0.001 s"``): a scalar named as in :data:`RATE_NAMES_HZ` or
        :data:`PERIOD_NAMES_S` in a MATLAB, HDF5 (also a root attribute) or ``.npz``
        file. :func:`sample_rate` uses it when there is no time column. The rate is
        nan when the stored value gives none (``Ts = 0``), so that the message can say
        what the file holds.
    """

    path: Path
    columns: dict[str, np.ndarray] = field(repr=False)
    time_column: str | None = None
    labels: dict[str, str] = field(default_factory=dict, repr=False)
    stored_rate: tuple[float, str] | None = None

    def label(self, key: str) -> str:
        """How column ``key`` is named in messages: ``column 'u'`` or ``column 2``."""
        return self.labels.get(key, f"column {key!r}")

    # Tables compare by identity: comparing columns element-wise has no single answer.
    __eq__ = object.__eq__
    __hash__ = object.__hash__

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.columns[name]
        except KeyError:
            raise DataError(_unknown_column(self.path, name, list(self.columns))) from None

    def __iter__(self) -> Iterator[str]:
        return iter(self.columns)

    def __len__(self) -> int:
        return len(self.columns)

    @property
    def n_rows(self) -> int:
        """Number of data rows (samples)."""
        return len(next(iter(self.columns.values()))) if self.columns else 0

    @property
    def time(self) -> np.ndarray | None:
        """The time column in seconds (converted from the unit its name states, see
        :func:`time_unit`), or None if the file had none."""
        if self.time_column is None:
            return None
        t = self.columns[self.time_column]
        _, seconds = time_unit(self.time_column)
        return t if seconds == 1.0 else t * seconds


def read_columns(
    path: str | Path,
    columns: Sequence[str] | None = None,
    *,
    time_column: str | None = "t",
) -> Table:
    """Read named numeric columns from a CSV, MATLAB, HDF5 or NumPy ``.npz`` file.

    Parameters
    ----------
    path : str or Path
        The file. The format follows the name ending: ``.csv``/``.txt``/``.dat``/``.tsv``
        (text: comma, semicolon, tab or whitespace separated, sniffed from the first row;
        lines starting with ``#`` before it are comments; the first row names the columns,
        or holds numbers, and then the file has no header and its columns are known by
        number only, as public identification records such as DaISy's ``.dat`` files
        come; semicolon-separated numbers with decimal commas and no points are read
        with decimal commas), ``.mat`` (MATLAB v5 through :func:`scipy.io.loadmat`,
        v7.3 through h5py), ``.h5``/``.hdf5`` (datasets by name; nested paths such as
        ``"run1/u"`` allowed) and ``.npz``.
    columns : sequence of str, optional
        The columns to read, by name or, in text files, by number counted from 1 as
        MATLAB, awk and spreadsheets count (``"1"`` is the first column): a name found in
        the header wins, else a whole number selects by position. The returned table is
        keyed by the strings given here. None reads every numeric vector in the file
        (a headerless text file's columns are then named ``"1"``, ``"2"``, ...).
    time_column : str or None, default "t"
        Name (or, in text files, number) of the time column, in seconds unless its name
        states another unit (``"t [ms]"``, ``"time_us"``: :func:`time_unit`). It is read as well
        when the file has it, and is then available as :attr:`Table.time`; a file without
        it is not an error here (pass the sample rate to :func:`sample_rate` instead).

    Returns
    -------
    Table
        The columns as float64 arrays of equal length.

    Raises
    ------
    TypeError
        If a column or the time column is not given as a string.
    DataError
        If the file is missing, unreadable or garbled; a column is unknown (the message
        lists the available ones, or the column numbers of a headerless file); a row has
        more or fewer fields than the first (every row is checked); a cell is not a number
        or is NaN/inf (the message gives the first bad data row, 1-based); the columns have
        unequal lengths; or there are no data rows.

    Examples
    --------
    >>> table = read_columns("run.csv", ["u", "y"])        # doctest: +SKIP
    >>> fs = sample_rate(table)                             # doctest: +SKIP
    """
    if time_column is not None and not isinstance(time_column, str):
        raise TypeError(f"time_column must be a name or a number written as a string, not "
                        f"{type(time_column).__name__} {time_column!r}")
    path = Path(path)
    if not path.exists():
        blocker = next((p for p in path.parents if p.is_file()), None)
        if blocker is not None:
            raise DataError(f"{str(path)!r}: cannot read: {str(blocker)!r} in its path is a "
                            "file, not a folder")
        raise DataError(f"{str(path)!r}: no such file")
    if path.is_dir():
        raise DataError(f"{str(path)!r}: is a folder, not a data file")
    if not path.is_file():
        raise DataError(f"{str(path)!r}: is not a regular file (a pipe or a device?)")
    if columns is not None:
        if isinstance(columns, str):
            columns = [columns]
        columns = list(columns)
        for c in columns:
            if not isinstance(c, str):
                raise TypeError(f"columns must be names or numbers written as strings "
                                f"('2' for the second column), not {type(c).__name__} {c!r}")
        columns = list(dict.fromkeys(columns))
        if not columns:
            raise DataError(f"{str(path)!r}: no columns requested")
    wanted = None if columns is None else list(columns)
    if wanted is not None and time_column and time_column not in wanted:
        optional_time = time_column
    else:
        optional_time = None

    suffix = path.suffix.lower()
    if suffix in (".csv", ".txt", ".dat", ".tsv"):
        raw = _read_csv(path, wanted, optional_time)
    elif suffix == ".mat":
        raw = _read_mat(path, wanted, optional_time)
    elif suffix in (".h5", ".hdf5"):
        raw = _read_hdf5(path, wanted, optional_time, transpose=False)
    elif suffix == ".npz":
        raw = _read_npz(path, wanted, optional_time)
    elif suffix == ".parquet":
        from ehss.io.tables import read_parquet

        raw = _Raw(read_parquet(path, wanted, optional_time))
    else:
        raise DataError(
            f"{str(path)!r}: unknown file type {suffix or '(none)'!r}; "
            f"accepted: {', '.join(SUPPORTED_SUFFIXES)}"
        )
    table = _finish(path, raw)
    has_time = bool(time_column) and time_column in table.columns
    stored = None if has_time else _stored_rate(path, suffix)
    return Table(path=path, columns=table.columns, time_column=time_column if has_time else None,
                 labels=raw.labels, stored_rate=stored)


def sample_rate(
    data: Table | np.ndarray | Sequence[float] | None,
    fs: float | None = None,
    *,
    rtol: float = 1e-2,
) -> float:
    """Sample rate in Hz from a time column or from ``fs``, and check that they agree.

    Parameters
    ----------
    data : Table, array_like of float or None
        A table (its time column is used if it has one) or a time vector in seconds.
    fs : float, optional
        The sample rate given by the user (Hz).
    rtol : float, default 0.01
        Relative tolerance on each time step (against the median step), and between the
        rate from the time column and ``fs``.

    Returns
    -------
    float
        The sample rate in Hz: ``fs`` if given, else ``(n - 1) / (t[-1] - t[0])``.

    Raises
    ------
    DataError
        If the time column has fewer than 2 samples, repeats a value, goes backwards, is
        unevenly sampled (the message names the first bad data row), is stored too
        coarsely for its step (large absolute times), or gives a sample rate outside
        ``SAMPLE_RATE_RANGE_HZ`` (1e-9 to 1e9 Hz; a step of 1e-310 s or 1e300 s means the
        column is not in seconds); if ``fs`` is not in that range; if the time column and
        ``fs`` disagree; or if neither is available.
    """
    where = ""
    if isinstance(data, Table):
        where = f"{str(data.path)!r}: "
        name = data.time_column
        t = data.time
    elif data is None:
        name, t = None, None
    else:
        name = "t"
        t = np.asarray(data, dtype=np.float64)
    lo_fs, hi_fs = SAMPLE_RATE_RANGE_HZ
    if fs is not None:
        try:
            fs = float(fs)
        except (TypeError, ValueError):
            raise DataError(f"sample rate {fs=} must be a number in Hz") from None
        if not (math.isfinite(fs) and lo_fs <= fs <= hi_fs):
            raise DataError(f"sample rate {fs=} Hz must be in [{lo_fs:g}, {hi_fs:g}] Hz")
    stored = data.stored_rate if isinstance(data, Table) else None
    if t is None and stored is not None:
        rate, what = stored
        if fs is not None and abs(rate - fs) > rtol * fs:
            raise DataError(f"{where}the file stores {what}, a sample rate of {rate:.6g} Hz, "
                            f"but --fs is {fs:.6g} Hz; drop --fs or make them agree")
        if fs is None:
            if not math.isfinite(rate):
                raise DataError(f"{where}the file stores {what}, which is no sample time or "
                                "rate; pass --fs HZ (or --time-column COL)")
            if not lo_fs <= rate <= hi_fs:
                raise DataError(f"{where}the file stores {what}: a sample rate of {rate:.6g} "
                                f"Hz, outside [{lo_fs:g}, {hi_fs:g}] Hz; pass --fs HZ")
            return rate
    if t is None:
        if fs is None:
            raise DataError(f"{where}no time column to get the sample rate from; name it "
                            f"with --time-column COL or pass --fs HZ"
                            + _time_column_hint(data))
        return fs
    fs_t = _rate_from_time(t, where, name or "t", rtol)
    if fs is not None:
        if abs(fs_t - fs) > rtol * fs:
            raise DataError(
                f"{where}the time column {name!r} gives a sample rate of {fs_t:.6g} Hz but "
                f"--fs is {fs:.6g} Hz; drop one or make them agree"
            )
        return fs
    return fs_t


def _time_column_hint(data: object) -> str:
    """`` (the file has 'time_s')`` when a column of ``data`` is named like a time."""
    if not isinstance(data, Table):
        return ""
    like = [c for c in data.columns if re.match(r"(t|time)\b|(t|time)[_\s\[(/]", c, re.I)]
    return f" (the file has {', '.join(repr(c) for c in like)})" if like else ""


def _rate_from_time(t: np.ndarray, where: str, name: str, rtol: float) -> float:
    col = f"{where}time column {name!r}"
    if t.ndim != 1 or t.size < 2:
        raise DataError(f"{col} needs at least 2 samples")
    if not np.all(np.isfinite(t)):
        row = int(np.flatnonzero(~np.isfinite(t))[0]) + 1
        raise DataError(f"{col}: non-finite value at data row {row}")
    steps = np.diff(t)
    # Large absolute times (e.g. Unix time in seconds) may be stored more coarsely than
    # the step: the column then looks repeated or uneven, so say what is wrong.
    span = float(t[-1] - t[0])
    resolution = float(np.spacing(np.max(np.abs(t))))
    if span > 0 and resolution > 0.1 * rtol * span / (t.size - 1):
        raise DataError(
            f"{col} reaches {float(np.max(np.abs(t))):.6g} s, where a float resolves only "
            f"{resolution:.3g} s, too coarse for its step of {span / (t.size - 1):.6g} s; "
            "subtract the start time from the column"
        )
    back = np.flatnonzero(steps <= 0)
    if back.size:
        k = int(back[0])
        if steps[k] == 0:
            raise DataError(f"{col} repeats the time {float(t[k])!r} s at data rows {k + 1} and "
                            f"{k + 2}; it must increase by one sample step per row"
                            + (" (it is constant)" if np.all(steps == 0) else ""))
        raise DataError(f"{col} goes backwards from {float(t[k])!r} s at data row {k + 1} "
                        f"to {float(t[k + 1])!r} s at row {k + 2}; it must increase")
    dt = float(np.median(steps))
    lo_fs, hi_fs = SAMPLE_RATE_RANGE_HZ
    if not 1.0 / hi_fs <= dt <= 1.0 / lo_fs:
        with np.errstate(over="ignore", divide="ignore"):
            rate = np.float64(1.0) / np.float64(dt)
        raise DataError(
            f"{col} has a typical step of {dt:.6g} s, a sample rate of {rate:.6g} Hz; "
            f"accepted rates are {lo_fs:g} to {hi_fs:g} Hz (is the column in seconds?)"
        )
    bad = np.flatnonzero(np.abs(steps - dt) > rtol * dt)
    if bad.size:
        ratios = steps[bad] / dt
        whole = (np.round(ratios) >= 2) & (np.abs(ratios - np.round(ratios)) < 0.1)
        if whole.any():  # whole steps missing: a gap, whatever else is uneven
            k = int(bad[np.flatnonzero(whole)[0]])
            ratio = float(steps[k] / dt)
            raise DataError(
                f"{col} jumps from {float(t[k])!r} s at data row {k + 1} to "
                f"{float(t[k + 1])!r} s at row {k + 2}, {ratio:.3g} typical steps "
                f"({dt:.6g} s): {round(ratio) - 1} sample(s) missing there; split the "
                "record at the gap"
            )
        k = int(bad[0])
        spread = float(np.max(np.abs(steps - dt)) / dt)
        raise DataError(
            f"{col} is unevenly sampled: the step from data row {k + 1} to row {k + 2} "
            f"is {steps[k]:.6g} s, the typical step {dt:.6g} s (steps differ from it by "
            f"up to {100 * spread:.3g} %); if the samples were taken at a fixed rate and "
            "only the time stamps jitter, pass --fs HZ with --time-column '' to ignore them"
        )
    return (t.size - 1) / float(t[-1] - t[0])


# --------------------------------------------------------------------------- helpers
#: Names of a scalar sample rate (Hz) a MATLAB, HDF5 or .npz file may store.
RATE_NAMES_HZ = ("fs", "Fs", "FS", "sample_rate", "sampling_rate", "srate")
#: Names of a scalar sample time (s): MATLAB's iddata calls it Ts.
PERIOD_NAMES_S = ("Ts", "ts", "dt", "sample_time")


def _stored_rate(path: Path, suffix: str) -> tuple[float, str] | None:
    """A sample rate stored in the file beside its columns, if any (see Table)."""
    found: dict[str, Any] = {}
    names = RATE_NAMES_HZ + PERIOD_NAMES_S
    try:
        if suffix in (".h5", ".hdf5") or (suffix == ".mat" and _is_hdf5(path)):
            import h5py

            with h5py.File(path, "r") as fh:
                for n in names:
                    if n in fh and isinstance(fh[n], h5py.Dataset) and fh[n].size == 1:
                        found[n] = fh[n][()]
                    elif n in fh.attrs and np.size(fh.attrs[n]) == 1:
                        found[n] = fh.attrs[n]
        elif suffix == ".mat":
            import scipy.io

            present = [v[0] for v in scipy.io.whosmat(path) if v[0] in names
                       and int(np.prod(v[1])) == 1]
            if present:
                found = scipy.io.loadmat(path, variable_names=present)
        elif suffix == ".npz":
            with np.load(path, allow_pickle=False) as archive:
                found = {n: archive[n] for n in names
                         if n in archive.files and archive[n].size == 1}
    except (OSError, ValueError, TypeError, KeyError, NotImplementedError):
        return None  # the columns were read: a stored rate is only a convenience
    unusable = None
    for n in names:
        if n not in found:
            continue
        try:
            value = float(np.asarray(found[n], dtype=np.float64).ravel()[0])
        except (TypeError, ValueError):
            continue
        unit = "Hz" if n in RATE_NAMES_HZ else "s"
        if not (math.isfinite(value) and value > 0):
            unusable = unusable or (math.nan, f"{n!r} = {value:g} {unit}")
            continue
        if n in RATE_NAMES_HZ:
            return value, f"{n!r} = {value:g} Hz"
        return 1.0 / value, f"{n!r} = {value:g} s"
    return unusable  # a stored value that gives no rate: said so if the rate is needed




@dataclass(frozen=True)
class _Raw:
    """Columns as read, before the common checks (lengths, finiteness, float64).

    ``labels`` gives how a column is named in messages when that differs from its key
    (a column chosen by number: ``column 2 ('u')``; a headerless file: ``column 2``).
    """

    columns: dict[str, np.ndarray]
    labels: dict[str, str] = field(default_factory=dict)


def _unknown_column(path: Path, name: str, available: list[str]) -> str:
    shown = ", ".join(repr(a) for a in available[:30])
    if len(available) > 30:
        shown += f", ... ({len(available)} in all)"
    hint = ""
    if _column_number(name) is not None and path.suffix.lower() not in _TEXT_SUFFIXES:
        hint = (" (column numbers select columns of text files only; name the variable, "
                "or a column of a stored matrix as NAME:K, K counted from 1)")
    return f"{str(path)!r}: no column {name!r}; available: {shown or '(none)'}{hint}"


def _column_number(spec: str) -> int | None:
    """The whole number written in ``spec`` (``"2"``, ``" 2 "``), or None."""
    text = spec.strip()
    return int(text) if text.isascii() and text.isdigit() else None


def _finish(path: Path, raw: _Raw) -> Table:
    cols = raw.columns
    if not cols:
        raise DataError(f"{str(path)!r}: no numeric columns found")
    lengths = {name: a.shape[0] for name, a in cols.items()}
    if len(set(lengths.values())) > 1:
        desc = ", ".join(f"{n!r}: {k}" for n, k in lengths.items())
        raise DataError(f"{str(path)!r}: columns have unequal lengths ({desc})")
    if next(iter(lengths.values())) == 0:
        raise DataError(f"{str(path)!r}: no data rows")
    out: dict[str, np.ndarray] = {}
    for name, a in cols.items():
        a = np.ascontiguousarray(a, dtype=np.float64)
        finite = np.isfinite(a)
        if not finite.all():
            row = int(np.flatnonzero(~finite)[0])
            label = raw.labels.get(name, f"column {name!r}")
            raise DataError(
                f"{str(path)!r}: {label} has a non-finite value ({float(a[row])!r}) "
                f"at data row {row + 1}"
            )
        a.flags.writeable = False
        out[name] = a
    return Table(path=path, columns=out)


def _matrix_column(spec: str, available: list[str]) -> tuple[str, int] | None:
    """``(NAME, K)`` if ``spec`` is ``NAME:K``, column K (from 1) of the stored matrix
    NAME (MATLAB's ``NAME(:, K)``), and NAME is stored; else None."""
    name, sep, k = spec.rpartition(":")
    number = _column_number(k) if sep else None
    if number is None or number < 1 or name not in available:
        return None
    return name, number


def _stored(spec: str, available: list[str]) -> str:
    """The stored variable that holds the column ``spec`` (itself, or NAME of NAME:K)."""
    if spec in available:
        return spec
    m = _matrix_column(spec, available)
    return spec if m is None else m[0]


def _column(path: Path, spec: str, value, available: list[str]) -> np.ndarray:
    """The column ``spec`` from its stored ``value``: a vector, or NAME:K of a matrix
    whose rows are the samples."""
    m = None if spec in available else _matrix_column(spec, available)
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


def _select(
    path: Path,
    available: list[str],
    wanted: list[str] | None,
    optional: str | None,
) -> list[str]:
    if wanted is None:
        return list(available)
    for name in wanted:
        if name not in available and _matrix_column(name, available) is None:
            raise DataError(_unknown_column(path, name, available))
    names = list(wanted)
    if optional is not None and (optional in available
                                 or _matrix_column(optional, available) is not None):
        names.insert(0, optional)
    return names


# ---- CSV -------------------------------------------------------------------------------

def _read_text(path: Path) -> str:
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise DataError(f"{str(path)!r}: cannot read: {exc.strerror or exc}") from None
    if b"\x00" in data[:4096]:
        raise DataError(f"{str(path)!r}: not a text CSV file (binary content)")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        try:
            return data.decode("latin-1")
        except UnicodeDecodeError:  # pragma: no cover - latin-1 decodes any byte
            raise DataError(f"{str(path)!r}: not a readable text file") from None


_TEXT_SUFFIXES = (".csv", ".txt", ".dat", ".tsv")


def _split_fn(first: str):
    """Delimiter sniffed from the first row, and a function splitting a line on it.

    A semicolon wins over a comma (files with decimal commas separate by semicolons);
    without comma, semicolon or tab the fields are separated by runs of whitespace.
    """
    if ";" in first:
        delim = ";"
    elif "," in first:
        delim = ","
    elif "\t" in first:
        delim = "\t"
    else:
        delim = None
    if delim is None:
        return None, lambda line: line.split()
    def split(line: str) -> list[str]:
        return next(csv.reader([line], delimiter=delim))
    return delim, split


def _read_csv(path: Path, wanted: list[str] | None, optional: str | None) -> _Raw:
    text = _read_text(path)
    lines = text.splitlines()
    i = 0
    while i < len(lines) and (not lines[i].strip() or lines[i].lstrip().startswith("#")):
        i += 1
    if i == len(lines):
        raise DataError(f"{str(path)!r}: empty file (no header row)")
    delim, split = _split_fn(lines[i])
    first = [h.strip().strip('"').strip("'").strip() for h in split(lines[i])]
    decimal_comma = _decimal_comma(delim, lines[i + 1 :])
    headerless = _looks_numeric([h.replace(",", ".") for h in first] if decimal_comma
                                else first)
    if headerless:
        # No header: the columns are known by number, counted from 1.
        header = [str(k) for k in range(1, len(first) + 1)]
        data_lines = lines[i:]
    else:
        header = first
        data_lines = lines[i + 1 :]
        if any(not h for h in header):
            k = header.index("")
            raise DataError(
                f"{str(path)!r}: the header row has an empty name in field {k + 1}; "
                "the first row must name every column (or hold only numbers, for a file "
                "without header)"
            )
        if len(set(header)) != len(header):
            dup = next(h for h in header if header.count(h) > 1)
            raise DataError(f"{str(path)!r}: column name {dup!r} appears twice in the header")
    idx, keys, labels = _resolve_text_columns(path, header, headerless, wanted, optional)
    # Trailing blank lines are not rows.
    while data_lines and not data_lines[-1].strip():
        data_lines.pop()
    if not data_lines:
        raise DataError(f"{str(path)!r}: no data rows after the header")
    parsed_lines = [line.replace(",", ".") for line in data_lines] if decimal_comma \
        else data_lines
    # Fast path: numpy parses the whole block; on any failure, a slow pass finds the cell.
    try:
        with np.errstate(all="ignore"):
            block = np.loadtxt(
                parsed_lines,
                delimiter=delim,
                usecols=idx,
                dtype=np.float64,
                ndmin=2,
                comments=None,
                quotechar='"' if delim else None,
            )
        if block.shape != (len(data_lines), len(idx)):
            raise ValueError("shape")
        n_fields_ok = bool(np.all(_field_counts(data_lines, delim, split) == len(header)))
    except ValueError:
        block = None
        n_fields_ok = False
    if block is None or not n_fields_ok:
        _diagnose_csv(path, data_lines, split, header, [labels[k] for k in keys], idx,
                      headerless, decimal_comma)
        raise DataError(f"{str(path)!r}: cannot parse the data rows")  # pragma: no cover
    return _Raw({k: block[:, j].copy() for j, k in enumerate(keys)}, labels)


def _resolve_text_columns(
    path: Path, header: list[str], headerless: bool, wanted: list[str] | None,
    optional: str | None,
) -> tuple[list[int], list[str], dict[str, str]]:
    """Field indices, table keys and message labels of the requested columns.

    A request is a header name or a column number counted from 1; the key is the
    request as given, so ``table[request]`` finds it.
    """
    def label(j: int) -> str:
        return f"column {j + 1}" if headerless else f"column {header[j]!r}"

    def find(spec: str) -> int | None:
        if not headerless and spec in header:
            return header.index(spec)
        k = _column_number(spec)
        if k is not None and 1 <= k <= len(header):
            return k - 1
        return None

    if wanted is None:
        return list(range(len(header))), list(header), {h: label(j) for j, h in
                                                        enumerate(header)}
    idx: list[int] = []
    keys: list[str] = []
    labels: dict[str, str] = {}
    for spec in wanted:
        j = find(spec)
        if j is None:
            raise DataError(_no_text_column(path, header, headerless, spec))
        idx.append(j)
        keys.append(spec)
        labels[spec] = label(j)
    if optional is not None:
        j = find(optional)
        if j is not None and optional not in keys:
            idx.insert(0, j)
            keys.insert(0, optional)
            labels[optional] = label(j)
    return idx, keys, labels


def _no_text_column(path: Path, header: list[str], headerless: bool, spec: str) -> str:
    n = len(header)
    k = _column_number(spec)
    if k is not None:
        if k == 0:
            return (f"{str(path)!r}: there is no column 0; columns are numbered from 1 "
                    f"(the first) to {n}")
        return f"{str(path)!r}: no column {k}; the file has {n} column{'s' if n > 1 else ''}"
    if headerless:
        return (f"{str(path)!r}: no column named {spec!r}: the file has no header row (its "
                f"first row holds numbers), so its {n} columns are known by number only, "
                f"1 to {n} (1 is the first)")
    return _unknown_column(path, spec, header) + (
        f", or a column number 1 to {n}")


def _decimal_comma(delim: str | None, lines: list[str]) -> bool:
    """True for a semicolon-separated file whose numbers have decimal commas (as
    spreadsheets write them in much of Europe): commas in it, and no point."""
    if delim != ";":
        return False
    text = "\n".join(lines)
    return "," in text and "." not in text


def _looks_numeric(header: list[str]) -> bool:
    try:
        [float(h) for h in header]
    except ValueError:
        return False
    return True


def _field_counts(data_lines: list[str], delim: str | None, split) -> np.ndarray:
    """Number of fields on every data line (all of them, not a sample)."""
    n = len(data_lines)
    if delim is not None:
        if any('"' in line for line in data_lines):  # quoted fields: let csv split them
            return np.fromiter((len(split(line)) for line in data_lines), np.int64, n)
        return np.fromiter((line.count(delim) for line in data_lines), np.int64, n) + 1
    # Whitespace-separated: str.split counts the runs of non-blank characters.
    return np.fromiter(map(len, map(str.split, data_lines)), np.int64, n)


def _diagnose_csv(path, data_lines, split, header, labels, idx, headerless,
                  decimal_comma) -> None:
    n = len(header)
    reference = "the first row" if headerless else "the header"
    for r, line in enumerate(data_lines, start=1):
        fields = split(line)
        if not line.strip():
            raise DataError(f"{str(path)!r}: data row {r} is empty")
        if len(fields) != n:
            raise DataError(
                f"{str(path)!r}: data row {r} has {len(fields)} fields, {reference} has {n} "
                "(unequal column lengths or a stray separator)"
            )
        for label, j in zip(labels, idx, strict=True):
            cell = fields[j].strip()
            try:
                float(cell.replace(",", ".") if decimal_comma else cell)
            except ValueError:
                shown = cell if cell else "(empty)"
                how = " (read with decimal commas)" if decimal_comma else ""
                raise DataError(
                    f"{str(path)!r}: {label}, data row {r}: {shown!r} is not a number{how}"
                ) from None


# ---- MATLAB / HDF5 / NPZ ------------------------------------------------------------------


def _as_vector(path: Path, name: str, value) -> np.ndarray | None:
    """A 1-D float array from a stored array, or None if it is not a numeric vector."""
    a = np.asarray(value)
    if a.dtype.kind not in "biuf":
        return None
    if a.ndim == 0:
        return None
    if a.ndim > 1:
        if sum(s != 1 for s in a.shape) > 1:
            return None
        a = a.reshape(-1)
    return a.astype(np.float64, copy=False)


def _vector_or_error(path: Path, name: str, value) -> np.ndarray:
    a = _as_vector(path, name, value)
    if a is None:
        shape = "x".join(str(s) for s in np.shape(value)) or "scalar"
        kind = getattr(np.asarray(value).dtype, "kind", "?")
        what = "numeric" if kind in "biuf" else f"non-numeric ({np.asarray(value).dtype})"
        raise DataError(
            f"{str(path)!r}: {name!r} is a {shape} {what} array, not a numeric vector"
        )
    return a


def _read_mat(path: Path, wanted, optional) -> _Raw:
    with open(path, "rb") as fh:
        head = fh.read(1024)
    if _is_hdf5(path, head):
        return _read_hdf5(path, wanted, optional, transpose=True)
    import scipy.io

    try:
        content = scipy.io.loadmat(path, simplify_cells=True)
    except NotImplementedError:  # pragma: no cover - v7.3 without HDF5 signature
        return _read_hdf5(path, wanted, optional, transpose=True)
    except Exception as exc:  # scipy raises many types on garbage
        raise DataError(f"{str(path)!r}: not a readable MATLAB file ({exc})") from None
    flat = _flatten_mapping({k: v for k, v in content.items() if not k.startswith("__")})
    return _pick(path, flat, wanted, optional)


def _flatten_mapping(obj: Mapping, prefix: str = "") -> dict:
    out = {}
    for key, value in obj.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            out.update(_flatten_mapping(value, prefix=f"{name}/"))
        else:
            out[name] = value
    return out


def _pick(path: Path, flat: dict, wanted, optional) -> _Raw:
    if wanted is None:
        cols = {}
        for name, value in flat.items():
            a = _as_vector(path, name, value)
            if a is not None:
                cols[name] = a
        return _Raw(cols)
    available = list(flat)
    names = _select(path, available, wanted, optional)
    return _Raw({n: _column(path, n, flat[_stored(n, available)], available) for n in names})


def _is_hdf5(path: Path, head: bytes | None = None) -> bool:
    if head is None:
        with open(path, "rb") as fh:
            head = fh.read(1024)
    # The superblock sits at 0, 512, 1024, ... (MATLAB v7.3 puts a 512-byte header first).
    return head.startswith(_HDF5_SIGNATURE) or head[512:520] == _HDF5_SIGNATURE


def _read_hdf5(path: Path, wanted, optional, *, transpose: bool) -> _Raw:
    import h5py

    try:
        fh = h5py.File(path, "r")
    except OSError as exc:
        raise DataError(f"{str(path)!r}: not a readable HDF5 file ({exc})") from None
    with fh:
        names: list[str] = []

        def visit(name, obj):
            if isinstance(obj, h5py.Dataset) and not name.startswith("#"):
                names.append(name)

        fh.visititems(visit)
        if wanted is None:
            cols = {}
            for name in names:
                ds = fh[name]
                if ds.dtype.kind in "biuf" and _is_vector_shape(ds.shape):
                    # MATLAB's char/logical arrays carry a MATLAB_class attribute; keep
                    # only numeric classes.
                    if transpose and _matlab_class(ds) not in _MATLAB_NUMERIC:
                        continue
                    cols[name] = _load_ds(ds, transpose)
            return _Raw(cols)
        chosen = _select(path, names, wanted, optional)
        # a matrix whose columns are asked for is read once
        stored = {b: _load_ds(fh[b], transpose) for b in {_stored(n, names) for n in chosen}}
        return _Raw({n: _column(path, n, stored[_stored(n, names)], names) for n in chosen})


_MATLAB_NUMERIC = {
    None, "double", "single", "int8", "uint8", "int16", "uint16", "int32", "uint32",
    "int64", "uint64",
}


def _matlab_class(ds) -> str | None:
    value = ds.attrs.get("MATLAB_class")
    if value is None:
        return None
    return value.decode() if isinstance(value, bytes) else str(value)


def _is_vector_shape(shape: tuple[int, ...]) -> bool:
    return len(shape) >= 1 and sum(s != 1 for s in shape) <= 1


def _load_ds(ds, transpose: bool) -> np.ndarray:
    a = ds[()]
    # MATLAB v7.3 stores column-major arrays, so an N-by-1 column arrives as shape (1, N);
    # transposing restores MATLAB's view (only matters for the error message on matrices).
    return a.T if transpose and np.ndim(a) >= 2 else a


def _read_npz(path: Path, wanted, optional) -> _Raw:
    # The file is opened here so that it is closed even when numpy refuses it.
    with open(path, "rb") as fh:
        try:
            archive = np.load(fh, allow_pickle=False)
        except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
            raise DataError(f"{str(path)!r}: not a readable .npz file ({exc})") from None
        if not isinstance(archive, np.lib.npyio.NpzFile):
            raise DataError(f"{str(path)!r}: not an .npz archive")
        with archive:
            try:
                if wanted is None:
                    flat = {k: archive[k] for k in archive.files}
                else:
                    names = _select(path, list(archive.files), wanted, optional)
                    flat = {b: archive[b] for b in {_stored(n, archive.files) for n in names}}
            except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
                raise DataError(f"{str(path)!r}: not a readable .npz file ({exc})") from None
    return _pick(path, flat, wanted, optional)
