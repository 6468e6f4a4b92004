"""A burst of NaN in a record, in every format a record comes in, through every command
that reads one: the one line names the file, the column and the first bad row as it
stands in the file (its data row counted from 1, saying so).

The bursts: a run in the middle of the output, in the time column, at the very start of
the input, at the very end of the output. Records are 600 samples at 500 Hz.
"""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import polars as pl
import pytest
import scipy.io

N = 600
FS = 500.0

#: (column, first bad index, last bad index + 1)
BURSTS = {
    "middle of y": ("y", 300, 320),
    "time column": ("t", 250, 260),
    "start of u": ("u", 0, 5),
    "end of y": ("y", N - 4, N),
}


def _columns(column: str, lo: int, hi: int) -> dict[str, np.ndarray]:
    t = np.arange(N) / FS
    cols = {"t": t, "u": np.sin(2 * np.pi * 7 * t), "y": np.cos(2 * np.pi * 5 * t)}
    cols[column][lo:hi] = np.nan
    return cols


def _text(path: Path, cols: dict[str, np.ndarray], sep: str, comma: bool) -> None:
    rows = [sep.join(repr(float(v)) for v in row) for row in zip(*cols.values(), strict=True)]
    text = sep.join(cols) + "\n" + "\n".join(rows) + "\n"
    path.write_text(text.replace(".", ",") if comma else text)


def _mat73(path: Path, cols: dict[str, np.ndarray]) -> None:
    """A MATLAB v7.3 file: HDF5 behind MATLAB's 512-byte header, row vectors."""
    with h5py.File(path, "w", userblock_size=512) as h:
        for name, a in cols.items():
            h[name] = a[None, :]
    head = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, HDF5 schema 1.00 ."
    with open(path, "r+b") as f:
        f.write(head.ljust(116) + b"\x00" * 8 + b"\x00\x02IM")


def _h5(path: Path, cols: dict[str, np.ndarray]) -> None:
    with h5py.File(path, "w") as h:
        for name, a in cols.items():
            h[name] = a


WRITERS = {
    "r.csv": lambda p, c: _text(p, c, ",", False),
    "r_semicolon.csv": lambda p, c: _text(p, c, ";", True),
    "r.mat": lambda p, c: scipy.io.savemat(p, c),
    "r73.mat": _mat73,
    "r.h5": _h5,
    "r.npz": lambda p, c: np.savez(p, **c),
    "r.parquet": lambda p, c: pl.DataFrame(c).write_parquet(p),
}

COMMANDS = {
    "identify": ["identify", "{f}", "--input", "u", "--output", "y", "--na", "2", "--nb",
                 "2", "--nc", "1", "--out", "m.json"],
    "frf": ["frf", "{f}", "--input", "u", "--output", "y", "--out", "h.csv"],
    "order": ["order", "{f}", "--input", "u", "--output", "y", "--na", "1-2", "--nb", "1",
              "--nc", "1", "--out", "table.csv"],
    "live": ["live", "--replay", "{f}", "--fields", "t=t,ref1=u,fb1=y", "--speed", "inf",
             "--quiet", "--report", "rep.json"],
}


def _cases() -> list[tuple[str, str, str]]:
    """Each burst in each format, the commands taken in turn so that every format also
    goes through every command (a Latin square: 28 cases, not 112)."""
    commands = list(COMMANDS)
    return [(burst, name, commands[(i + j) % len(commands)])
            for i, burst in enumerate(BURSTS) for j, name in enumerate(WRITERS)]


@pytest.mark.parametrize(("burst", "name", "command"), _cases())
def test_a_nan_burst_names_file_column_and_first_row(tmp_path, refused, burst, name,
                                                     command):
    column, lo, _ = BURSTS[burst]
    WRITERS[name](tmp_path / name, _columns(*BURSTS[burst]))
    argv = [a.replace("{f}", name) for a in COMMANDS[command]]
    refused(argv, tmp_path, repr(name), repr(column), "nan", f"data row {lo + 1}")


@pytest.fixture(scope="module")
def recording(tmp_path_factory, ehss_cli) -> Path:
    """A short ``ehss live --record`` recording (fields t, ref1, fb1)."""
    folder = tmp_path_factory.mktemp("rec")
    run = ehss_cli(["live", "--rig", "position", "--duration", "1", "--speed", "inf",
                    "--seed", "2", "--record", "good.h5", "--quiet"], folder)
    assert run.code == 0, run.err
    return folder / "good.h5"


@pytest.mark.parametrize(("field", "row"), [("fb1", 400), ("t", 0), ("ref1", 999)])
def test_a_nan_burst_in_a_live_recording(recording, tmp_path, refused, field, row):
    path = tmp_path / "rec.h5"
    path.write_bytes(recording.read_bytes())
    with h5py.File(path, "a") as h:
        names = json.loads(h.attrs["fields"])
        samples = h["samples"][...]
        samples[row:row + 10, names.index(field)] = np.nan
        h["samples"][...] = samples
    line = refused(["live", "--replay", "rec.h5", "--speed", "inf", "--quiet"], tmp_path,
                   "'rec.h5'", repr(field), "nan", f"sample row {row + 1}")
    if field != "t":
        assert f"(t = {row / 1000:g} s)" in line
