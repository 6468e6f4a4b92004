"""Read measured or simulated records: named float64 columns from text, MATLAB, HDF5,
NPZ and Parquet files, with the sample rate the file states.

The file name's ending chooses one reader, once: ``_text`` (comma, semicolon, tab or
whitespace separated, parsed by polars), ``_matlab`` (v5; v7.3 goes to ``_hdf5``),
``_hdf5``, ``_npz`` or ``_parquet``. Each opens the file once and returns its columns and
the sample rate stored beside them; :func:`read_columns` checks them alike (equal
lengths, finite values) and builds the :class:`Table`.

Every problem with a file becomes a :class:`~ehss.errors.DataError` that names the file,
the column and, where it applies, the first bad row counted as a user counts rows in a
spreadsheet: data row 1 is the first row after the header.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ehss._checks import SAMPLE_RATE_RANGE_HZ
from ehss.errors import DataError
from ehss.io._columns import PERIOD_NAMES_S, RATE_NAMES_HZ, Raw, Reader, unknown_column
from ehss.io._hdf5 import read_hdf5
from ehss.io._matlab import read_mat
from ehss.io._npz import read_npz
from ehss.io._parquet import read_parquet
from ehss.io._text import read_text

__all__ = [
    "Table", "read_columns", "sample_rate", "time_unit", "SUPPORTED_SUFFIXES",
    "RATE_NAMES_HZ", "PERIOD_NAMES_S", "TIME_UNITS_S",
]

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


#: The reader of each file name ending.
_READERS: dict[str, Reader] = {
    ".csv": read_text, ".txt": read_text, ".dat": read_text, ".tsv": read_text,
    ".mat": read_mat, ".h5": read_hdf5, ".hdf5": read_hdf5, ".npz": read_npz,
    ".parquet": read_parquet,
}
#: File name endings understood by :func:`read_columns`.
SUPPORTED_SUFFIXES = tuple(_READERS)


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
            raise DataError(unknown_column(self.path, name, list(self.columns))) from None

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
    """Read named numeric columns, and a sample rate stored beside them, from a text,
    MATLAB, HDF5, NumPy ``.npz`` or Parquet file.

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
        ``"run1/u"`` allowed), ``.npz`` and ``.parquet``. The file is opened once.
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
        The columns as float64 arrays of equal length, and :attr:`Table.stored_rate`
        when the file has no time column.

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
    _check_file(path)
    wanted = _requested(path, columns)
    optional_time = None
    if wanted is not None and time_column and time_column not in wanted:
        optional_time = time_column  # read along when the file has it
    reader = _READERS.get(path.suffix.lower())
    if reader is None:
        raise DataError(
            f"{str(path)!r}: unknown file type {path.suffix.lower() or '(none)'!r}; "
            f"accepted: {', '.join(SUPPORTED_SUFFIXES)}"
        )
    raw = reader(path, wanted, optional_time)
    checked = _checked(path, raw)
    has_time = bool(time_column) and time_column in checked
    return Table(path=path, columns=checked, time_column=time_column if has_time else None,
                 labels=raw.labels, stored_rate=None if has_time else raw.stored_rate)


def _check_file(path: Path) -> None:
    """Refuse a path that is no readable regular file, saying what it is instead."""
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


def _requested(path: Path, columns: Sequence[str] | str | None) -> list[str] | None:
    """The requested columns, each once and in order; None for every column."""
    if columns is None:
        return None
    columns = [columns] if isinstance(columns, str) else list(columns)
    for c in columns:
        if not isinstance(c, str):
            raise TypeError(f"columns must be names or numbers written as strings "
                            f"('2' for the second column), not {type(c).__name__} {c!r}")
    if not columns:
        raise DataError(f"{str(path)!r}: no columns requested")
    return list(dict.fromkeys(columns))



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
    fs = _given_rate(fs)
    stored = data.stored_rate if isinstance(data, Table) else None
    if t is None and stored is not None:
        return _stored_or_given(where, stored, fs, rtol)
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


def _given_rate(fs: float | None) -> float | None:
    """``fs`` as a float in the accepted range, or None if not given."""
    if fs is None:
        return None
    lo_fs, hi_fs = SAMPLE_RATE_RANGE_HZ
    try:
        rate = float(fs)  # a string or any other object: float() decides
    except (TypeError, ValueError):
        raise DataError(f"sample rate {fs=} must be a number in Hz") from None
    if not (math.isfinite(rate) and lo_fs <= rate <= hi_fs):
        raise DataError(f"sample rate fs={rate!r} Hz must be in [{lo_fs:g}, {hi_fs:g}] Hz")
    return rate


def _stored_or_given(where: str, stored: tuple[float, str], fs: float | None,
                     rtol: float) -> float:
    """The rate a file stores, checked against ``fs`` when that is given (then ``fs``)."""
    rate, what = stored
    if fs is not None:
        if abs(rate - fs) > rtol * fs:
            raise DataError(f"{where}the file stores {what}, a sample rate of {rate:.6g} Hz, "
                            f"but --fs is {fs:.6g} Hz; drop --fs or make them agree")
        return fs
    lo_fs, hi_fs = SAMPLE_RATE_RANGE_HZ
    if not math.isfinite(rate):
        raise DataError(f"{where}the file stores {what}, which is no sample time or "
                        "rate; pass --fs HZ (or --time-column COL)")
    if not lo_fs <= rate <= hi_fs:
        raise DataError(f"{where}the file stores {what}: a sample rate of {rate:.6g} "
                        f"Hz, outside [{lo_fs:g}, {hi_fs:g}] Hz; pass --fs HZ")
    return rate


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


def _checked(path: Path, raw: Raw) -> dict[str, np.ndarray]:
    """The columns as read-only contiguous float64 arrays, once they are checked: some
    columns, equally long, with rows, every value finite."""
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
    return out
