"""Data input and output: read named columns from measured records, write results.

Readers accept CSV, MATLAB (v5 and v7.3), HDF5, NumPy ``.npz`` and Parquet files. Writers
produce tables in the format named by the file's ending (CSV with a JSON sidecar,
Parquet, HDF5, ``.npz``, MATLAB), each with the same metadata, and JSON documents, all
atomically (a failed run never leaves a half-written file).
"""

from __future__ import annotations

from ehss.io.readers import SUPPORTED_SUFFIXES, Table, read_columns, sample_rate
from ehss.io.tables import TABLE_SUFFIXES, read_metadata
from ehss.io.writers import table_writers, to_jsonable, write_csv, write_json, write_table

__all__ = [
    "Table",
    "read_columns",
    "sample_rate",
    "SUPPORTED_SUFFIXES",
    "TABLE_SUFFIXES",
    "read_metadata",
    "write_csv",
    "write_table",
    "table_writers",
    "write_json",
    "to_jsonable",
]
