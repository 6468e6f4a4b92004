"""Columns of a Parquet file, read with polars."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from ehss.errors import DataError
from ehss.io._columns import Raw, unknown_column

__all__ = ["read_parquet"]


def read_parquet(path: Path, wanted: list[str] | None, optional: str | None) -> Raw:
    """Numeric columns of a Parquet file: a :class:`~ehss.io._columns.Reader` (Parquet
    stores no sample rate ehss looks for).

    Raises
    ------
    DataError
        If the file is not readable Parquet, a wanted column is missing (the message
        lists the available ones) or holds something other than numbers.
    """
    import polars as pl

    try:
        schema = pl.read_parquet_schema(path)
        available = [n for n, dtype in schema.items() if dtype.is_numeric()]
        names = available if wanted is None else _chosen(path, schema, available, wanted,
                                                         optional)
        frame = pl.read_parquet(path, columns=names)
    except (OSError, pl.exceptions.PolarsError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise DataError(f"{str(path)!r}: not a readable Parquet file ({first})") from None
    return Raw({name: frame[name].to_numpy() for name in names})


def _chosen(path: Path, schema: Mapping[str, object], available: list[str], wanted: list[str],
            optional: str | None) -> list[str]:
    for name in wanted:
        if name in schema and name not in available:
            raise DataError(f"{str(path)!r}: column {name!r} holds {schema[name]}, "
                            "not numbers")
        if name not in available:
            raise DataError(unknown_column(path, name, available))
    names = list(wanted)
    if optional is not None and optional in available:
        names.insert(0, optional)
    return names
