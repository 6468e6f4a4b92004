"""Data input and output: read named columns from measured records, write results.

Readers accept CSV, MATLAB (v5 and v7.3), HDF5 and NumPy ``.npz`` files; writers produce
plain CSV and JSON atomically (a failed run never leaves a half-written file).
"""

from __future__ import annotations

from ehss.io.readers import SUPPORTED_SUFFIXES, Table, read_columns, sample_rate
from ehss.io.writers import to_jsonable, write_csv, write_json

__all__ = [
    "Table",
    "read_columns",
    "sample_rate",
    "SUPPORTED_SUFFIXES",
    "write_csv",
    "write_json",
    "to_jsonable",
]
