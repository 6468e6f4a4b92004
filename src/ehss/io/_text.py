"""Columns of a text record: comma, semicolon, tab or whitespace separated, parsed by polars.

The layout is read from the first row (after blank lines and ``#`` comments): its
separator (a semicolon wins over a comma, files with decimal commas separate by
semicolons; without comma, semicolon or tab, runs of blanks separate), whether it names
the columns or already holds numbers (a headerless file, as DaISy's ``.dat`` records
come), and whether the numbers have decimal commas (semicolon-separated, commas in the
data and no point). polars then parses the data rows in one pass. When it refuses them,
or finds a hole, a slow pass over the rows finds the first bad one and says which it is
and why, counting data rows as a spreadsheet does (data row 1 follows the header).
"""

from __future__ import annotations

import csv
import io
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ehss.errors import DataError
from ehss.io._columns import Raw, column_number, unknown_column

__all__ = ["read_text"]

_BOM = b"\xef\xbb\xbf"
_SPACE_RUN = re.compile(rb"  +")


@dataclass(frozen=True)
class _Layout:
    """How the data rows of a text file are written.

    Attributes
    ----------
    header : list of str
        The column names (``"1"``, ``"2"``, ... for a headerless file).
    headerless : bool
        The first row holds numbers: columns are known by number only.
    separator : str or None
        ``","``, ``";"`` or ``"\\t"``; None for runs of blanks.
    decimal_comma : bool
        Numbers are written with decimal commas.
    """

    header: list[str]
    headerless: bool
    separator: str | None
    decimal_comma: bool

    def split(self, line: str) -> list[str]:
        """The fields of one line."""
        if self.separator is None:
            return line.split()
        return next(csv.reader([line], delimiter=self.separator))

    def label(self, j: int) -> str:
        """How field ``j`` (from 0) is named in messages."""
        return f"column {j + 1}" if self.headerless else f"column {self.header[j]!r}"


def read_text(path: Path, wanted: list[str] | None, optional: str | None) -> Raw:
    """Columns of a text file by header name or by number counted from 1 (a headerless
    file's are named ``"1"``, ``"2"``, ...): a :class:`~ehss.io._columns.Reader`.

    Raises
    ------
    DataError
        If the file is binary or empty, the header is malformed (an empty or repeated
        name), a column is unknown, or a data row has another number of fields than the
        first row, is empty, or holds a cell that is not a number.
    """
    data = _read_bytes(path)
    start, end = _first_row(data)
    if start == end:
        raise DataError(f"{str(path)!r}: empty file (no header row)")
    layout = _layout(path, _decode(data[start:end]).rstrip("\r"), data, end + 1)
    body = _rows(data, start if layout.headerless else end + 1)
    idx, keys, labels = _resolve(path, layout, wanted, optional)
    if not body:
        raise DataError(f"{str(path)!r}: no data rows after the header")
    columns = _parse(path, body, layout, idx)
    return Raw(dict(zip(keys, columns, strict=True)), labels)


def _read_bytes(path: Path) -> bytes:
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise DataError(f"{str(path)!r}: cannot read: {exc.strerror or exc}") from None
    if b"\x00" in data[:4096]:
        raise DataError(f"{str(path)!r}: not a text CSV file (binary content)")
    return data[len(_BOM):] if data.startswith(_BOM) else data


def _decode(raw: bytes) -> str:
    """Text as UTF-8 or, failing that, Latin-1 (which decodes any byte)."""
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


def _first_row(data: bytes) -> tuple[int, int]:
    """Where the first row starts and ends, after blank lines and ``#`` comments.

    Both are ``len(data)`` when the file holds no row.
    """
    start = 0
    while start < len(data):
        end = data.find(b"\n", start)
        end = len(data) if end < 0 else end
        line = data[start:end].strip()
        if line and not line.startswith(b"#"):
            return start, end
        start = end + 1
    return len(data), len(data)


def _rows(data: bytes, start: int) -> bytes:
    """The rows from offset ``start`` on, without the blank lines at the end of the file
    (the last row keeps its own trailing blanks); one copy of the bytes."""
    stop = len(data)
    while stop > start and data[stop - 1] in b" \t\r\n":
        stop -= 1
    if stop <= start:
        return b""
    end = data.find(b"\n", stop)
    return data[start:end if end >= 0 else len(data)]


def _layout(path: Path, first: str, data: bytes, rest: int) -> _Layout:
    """The layout read from the first row and the rows after it (from offset ``rest``
    of ``data``)."""
    separator = next((s for s in (";", ",", "\t") if s in first), None)
    probe = _Layout([], False, separator, False)
    fields = [f.strip().strip('"').strip("'").strip() for f in probe.split(first)]
    # spreadsheets in much of Europe: semicolons between numbers with decimal commas
    decimal_comma = (separator == ";" and data.find(b",", rest) >= 0
                     and data.find(b".", rest) < 0)
    if _all_numbers([f.replace(",", ".") for f in fields] if decimal_comma else fields):
        return _Layout([str(k) for k in range(1, len(fields) + 1)], True, separator,
                       decimal_comma)
    if "" in fields:
        raise DataError(
            f"{str(path)!r}: the header row has an empty name in field "
            f"{fields.index('') + 1}; the first row must name every column (or hold only "
            "numbers, for a file without header)"
        )
    if len(set(fields)) != len(fields):
        dup = next(h for h in fields if fields.count(h) > 1)
        raise DataError(f"{str(path)!r}: column name {dup!r} appears twice in the header")
    return _Layout(fields, False, separator, decimal_comma)


def _all_numbers(fields: list[str]) -> bool:
    """True if every field is a number as polars reads one (Python's ``1_000`` is not)."""
    if any("_" in f for f in fields):
        return False
    try:
        [float(f) for f in fields]
    except ValueError:
        return False
    return True


def _resolve(path: Path, layout: _Layout, wanted: list[str] | None,
             optional: str | None) -> tuple[list[int], list[str], dict[str, str]]:
    """Field indices, table keys and message labels of the requested columns.

    A request is a header name or a column number counted from 1; the key is the
    request as given, so ``table[request]`` finds it.
    """
    header = layout.header
    if wanted is None:
        return (list(range(len(header))), list(header),
                {h: layout.label(j) for j, h in enumerate(header)})
    requests = list(wanted)
    if optional is not None and optional not in requests \
            and _field(layout, optional) is not None:
        requests.insert(0, optional)
    idx = []
    for spec in requests:
        j = _field(layout, spec)
        if j is None:
            raise DataError(_no_column(path, layout, spec))
        idx.append(j)
    return idx, requests, {spec: layout.label(j) for spec, j in zip(requests, idx,
                                                                    strict=True)}


def _field(layout: _Layout, spec: str) -> int | None:
    """The field (from 0) that ``spec`` names: a header name wins over a number."""
    if not layout.headerless and spec in layout.header:
        return layout.header.index(spec)
    k = column_number(spec)
    return k - 1 if k is not None and 1 <= k <= len(layout.header) else None


def _no_column(path: Path, layout: _Layout, spec: str) -> str:
    n = len(layout.header)
    k = column_number(spec)
    if k == 0:
        return (f"{str(path)!r}: there is no column 0; columns are numbered from 1 "
                f"(the first) to {n}")
    if k is not None:
        return f"{str(path)!r}: no column {k}; the file has {n} column{'s' if n > 1 else ''}"
    if layout.headerless:
        return (f"{str(path)!r}: no column named {spec!r}: the file has no header row (its "
                f"first row holds numbers), so its {n} columns are known by number only, "
                f"1 to {n} (1 is the first)")
    return unknown_column(path, spec, layout.header) + f", or a column number 1 to {n}"


# ---- parsing ----------------------------------------------------------------------------

def _parse(path: Path, body: bytes, layout: _Layout, idx: list[int]) -> list[np.ndarray]:
    """The columns ``idx`` of the data rows, parsed by polars in one pass.

    Every column is parsed, those not asked for as text, so that polars sees each row's
    fields: a row with more fields than the first is refused, one with fewer leaves a
    hole (null). On either, the slow pass over the rows names the first bad one; a hole
    it finds nothing wrong with is an empty cell in a column not asked for.
    """
    import polars as pl

    names = layout.header
    schema: dict[str, type[pl.DataType]] = {name: pl.String for name in names}
    schema.update({names[j]: pl.Float64 for j in idx})
    refused = ""
    try:
        frame = pl.read_csv(
            io.BytesIO(_tidy(body, layout.separator)), has_header=False, schema=schema,
            separator=layout.separator or ",", decimal_comma=layout.decimal_comma,
            quote_char='"' if layout.separator else None, encoding="utf8-lossy",
        )
    except pl.exceptions.PolarsError as exc:
        frame, refused = None, (str(exc).strip().splitlines() or [type(exc).__name__])[0]
    if frame is None or any(frame[name].null_count() for name in names):
        _diagnose(path, body, layout, idx)
    if frame is None or any(frame[names[j]].null_count() for j in idx):
        why = refused or "a cell is missing"
        raise DataError(f"{str(path)!r}: cannot parse the data rows ({why})")
    return [frame[names[j]].to_numpy() for j in idx]


def _tidy(body: bytes, separator: str | None) -> bytes:
    """The rows as polars reads them: a whitespace-separated row's fields joined by
    commas (polars takes one character as one separator); in other files the spaces
    around fields dropped.
    """
    if separator is None:
        return b"\n".join(b",".join(line.split()) for line in body.split(b"\n"))
    if b" " not in body:
        return body
    # a run of spaces becomes one, then a space next to a separator or line end goes
    body = _SPACE_RUN.sub(b" ", body)
    for mark in (separator.encode(), b"\n", b"\r"):
        body = body.replace(b" " + mark, mark).replace(mark + b" ", mark)
    return body.strip(b" ")


def _diagnose(path: Path, body: bytes, layout: _Layout, idx: list[int]) -> None:
    """Raise on the first bad data row: empty, with another number of fields than the
    first row, or with a cell asked for that is not a number; return if there is none."""
    n = len(layout.header)
    reference = "the first row" if layout.headerless else "the header"
    how = " (read with decimal commas)" if layout.decimal_comma else ""
    for r, line in enumerate(_decode(body).splitlines(), start=1):
        if not line.strip():
            raise DataError(f"{str(path)!r}: data row {r} is empty")
        fields = layout.split(line)
        if len(fields) != n:
            raise DataError(
                f"{str(path)!r}: data row {r} has {len(fields)} fields, {reference} has {n} "
                "(unequal column lengths or a stray separator)"
            )
        for j in idx:
            cell = fields[j].strip()
            if not _all_numbers([cell.replace(",", ".") if layout.decimal_comma else cell]):
                raise DataError(f"{str(path)!r}: {layout.label(j)}, data row {r}: "
                                f"{cell or '(empty)'!r} is not a number{how}")
