"""Hostile input to ``ehss compensate --update RUN --previous DRIVE``, run as users run
it: a previous drive file that is missing, garbled, stripped of its sidecar or with its
sidecar edited, of another length or rate, with a NaN, in each table format; a gain
that means nothing; an output onto the previous drive or its sidecar. Each is one line
on stderr and exit 2 and leaves every file as it was.

The loop: the model file's own q^-2 (0.1 + 0.05 q^-1)/(1 - 1.5 q^-1 + 0.7 q^-2) at
1 kHz, the plant 10 % weaker; the first drive is made by the command, the run computed
from it, and the second drive (with its iteration record) made from that run.
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
import polars as pl
import pytest
import scipy.signal

from ehss.cli import main
from ehss.io import read_columns, write_csv

DT = 1e-3


def _plant(u: np.ndarray) -> np.ndarray:
    return 0.9 * scipy.signal.lfilter([0.0, 0.0, 0.1, 0.05], [1.0, -1.5, 0.7], u)


def _run_of(drive_file: Path, run: Path) -> None:
    u = np.asarray(read_columns(drive_file)["drive"])
    write_csv(run, {"t": np.arange(u.size) * DT, "reference": u, "output": _plant(u)})


@pytest.fixture(scope="module")
def loop(tmp_path_factory) -> Path:
    """m.json, r.csv, d0.csv (first drive), run0.csv (its run), d1.csv (the update, with
    its iteration record), run1.csv (the run of d1), and d1 as .parquet/.npz/.mat."""
    folder = tmp_path_factory.mktemp("loop")
    (folder / "m.json").write_text(json.dumps({
        "a": [1.0, -1.5, 0.7], "b": [0.1, 0.05], "c": [1.0], "delay": 2, "dt": DT,
        "band_hz": [0.0, 100.0]}))
    t = np.arange(1000) * DT
    r = 0.01 * np.sin(2 * np.pi * 5 * t) * np.exp(-(((t - 0.5) / 0.12) ** 2))
    write_csv(folder / "r.csv", {"t": t, "reference": r})
    base = ["compensate", str(folder / "m.json"), str(folder / "r.csv")]
    assert main([*base, "--out", str(folder / "d0.csv")]) == 0
    _run_of(folder / "d0.csv", folder / "run0.csv")
    for name in ("d1.csv", "d1.parquet", "d1.npz", "d1.mat"):
        assert main([*base, "--update", str(folder / "run0.csv"), "--previous",
                     str(folder / "d0.csv"), "--out", str(folder / name)]) == 0
    _run_of(folder / "d1.csv", folder / "run1.csv")
    return folder


def _copy(loop: Path, folder: Path) -> None:
    for p in loop.iterdir():
        shutil.copy2(p, folder / p.name)


def _update(previous: str = "d1.csv", run: str = "run1.csv", out: str = "d2.csv",
            *extra: str) -> list[str]:
    return ["compensate", "m.json", "r.csv", "--update", run, "--previous", previous,
            "--out", out, *extra]


def test_the_loop_itself_is_accepted(loop, tmp_path, ehss_cli):
    """The positive control: each previous drive format is taken as it was written."""
    _copy(loop, tmp_path)
    for k, name in enumerate(("d1.csv", "d1.parquet", "d1.npz", "d1.mat")):
        run = ehss_cli(_update(name, out=f"d2_{k}.csv"), tmp_path)
        assert run.code == 0, run.err
        assert (tmp_path / f"d2_{k}.csv").exists()


def _edit_sidecar(change: Callable[[dict], None]) -> Callable[[Path], None]:
    def edit(folder: Path) -> None:
        side = folder / "d1.json"
        doc = json.loads(side.read_text())
        change(doc)
        side.write_text(json.dumps(doc))
    return edit


def _set(key: str, value: object) -> Callable[[dict], None]:
    return lambda doc: doc["iteration"].__setitem__(key, value)


def _drive_rows(edit: Callable[[pl.DataFrame], pl.DataFrame]) -> Callable[[Path], None]:
    def change(folder: Path) -> None:
        path = folder / "d1.csv"
        path.write_text(edit(pl.read_csv(path)).write_csv())
    return change


def _nan_in_drive(df: pl.DataFrame) -> pl.DataFrame:
    drive = df["drive"].to_numpy().copy()
    drive[500:505] = np.nan
    return df.with_columns(pl.Series("drive", drive))


def _no_metadata(suffix: str) -> Callable[[Path], None]:
    def change(folder: Path) -> None:
        table = read_columns(folder / f"d1{suffix}")
        cols = {c: np.asarray(table[c]) for c in table.columns}
        if suffix == ".npz":
            np.savez(folder / "d1.npz", **cols)
        else:
            pl.DataFrame(cols).write_parquet(folder / "d1.parquet")
    return change


PREVIOUS: dict[str, tuple[Callable[[Path], None], str, tuple[str, ...]]] = {
    "missing": (lambda f: (f / "d1.csv").unlink(), "d1.csv", ("d1.csv",)),
    "garbled": (lambda f: (f / "d1.csv").write_bytes(bytes(range(256)) * 8), "d1.csv",
                ("d1.csv",)),
    "empty": (lambda f: (f / "d1.csv").write_bytes(b""), "d1.csv", ("d1.csv",)),
    "sidecar missing": (lambda f: (f / "d1.json").unlink(), "d1.csv", ("d1.csv",)),
    "sidecar garbled": (lambda f: (f / "d1.json").write_text("{not json"), "d1.csv",
                        ("d1.csv",)),
    "sidecar a list": (lambda f: (f / "d1.json").write_text("[1, 2]"), "d1.csv",
                       ("d1.csv",)),
    "sidecar without iteration": (_edit_sidecar(lambda d: d.pop("iteration")), "d1.csv",
                                  ("d1.csv", "iteration")),
    "sidecar gain missing": (_edit_sidecar(lambda d: d["iteration"].pop("gain")), "d1.csv",
                             ("d1.csv", "gain")),
    "sidecar gain text": (_edit_sidecar(_set("gain", "one")), "d1.csv", ("d1.csv", "gain")),
    "sidecar gain beyond 2": (_edit_sidecar(_set("gain", 5.0)), "d1.csv",
                              ("d1.csv", "gain")),
    "sidecar gain zero": (_edit_sidecar(_set("gain", 0.0)), "d1.csv", ("d1.csv", "gain")),
    "sidecar gain nan": (_edit_sidecar(_set("gain", float("nan"))), "d1.csv",
                         ("d1.csv", "gain")),
    "sidecar error negative": (_edit_sidecar(_set("base_rms_error", -1.0)), "d1.csv",
                               ("d1.csv", "base_rms_error")),
    "sidecar error text": (_edit_sidecar(_set("base_rms_error", "small")), "d1.csv",
                           ("d1.csv", "base_rms_error")),
    "sidecar halvings negative": (_edit_sidecar(_set("halvings", -1)), "d1.csv",
                                  ("d1.csv", "halvings")),
    "sidecar halvings text": (_edit_sidecar(_set("halvings", "two")), "d1.csv",
                              ("d1.csv", "halvings")),
    "sidecar log not a list": (_edit_sidecar(_set("log", "ok")), "d1.csv",
                               ("d1.csv", "iteration")),
    "drive shorter": (_drive_rows(lambda df: df.head(800)), "d1.csv", ("d1.csv",)),
    "drive nan": (_drive_rows(_nan_in_drive), "d1.csv",
                  ("d1.csv", "'drive'", "nan", "data row 501")),
    "drive at another rate": (_drive_rows(lambda df: df.with_columns(pl.col("t") * 2)),
                              "d1.csv", ("d1.csv", "Hz")),
    "correction column dropped": (_drive_rows(lambda df: df.drop("correction")), "d1.csv",
                                  ("d1.csv", "correction")),
    "drive column dropped": (_drive_rows(lambda df: df.drop("drive")), "d1.csv",
                             ("d1.csv", "drive")),
    "parquet without metadata": (_no_metadata(".parquet"), "d1.parquet",
                                 ("d1.parquet", "iteration")),
    "npz without metadata": (_no_metadata(".npz"), "d1.npz", ("d1.npz", "iteration")),
    "mat garbled": (lambda f: (f / "d1.mat").write_bytes(b"MATLAB 5.0" + bytes(300)),
                    "d1.mat", ("d1.mat",)),
    "a run as the previous drive": (lambda f: None, "run0.csv", ("run0.csv",)),
    "the reference as the previous drive": (lambda f: None, "r.csv", ("r.csv",)),
}


@pytest.mark.parametrize("case", list(PREVIOUS))
def test_a_bad_previous_drive_is_refused(loop, tmp_path, refused, case):
    _copy(loop, tmp_path)
    edit, previous, words = PREVIOUS[case]
    edit(tmp_path)
    refused(_update(previous), tmp_path, *words)


RUNS: dict[str, tuple[Callable[[Path], None], tuple[str, ...]]] = {
    "missing": (lambda f: (f / "run1.csv").unlink(), ("run1.csv",)),
    "garbled": (lambda f: (f / "run1.csv").write_bytes(b"\x00\xff" * 500), ("run1.csv",)),
    "nan in the output": (
        lambda f: (f / "run1.csv").write_text(
            _nan_in(pl.read_csv(f / "run1.csv"), "output").write_csv()),
        ("run1.csv", "'output'", "nan")),
    "shorter than the reference": (
        lambda f: (f / "run1.csv").write_text(pl.read_csv(f / "run1.csv").head(700)
                                              .write_csv()), ("run1.csv",)),
    "output column missing": (
        lambda f: (f / "run1.csv").write_text(pl.read_csv(f / "run1.csv").drop("output")
                                              .write_csv()), ("output",)),
}


def _nan_in(df: pl.DataFrame, column: str) -> pl.DataFrame:
    x = df[column].to_numpy().copy()
    x[300] = np.nan
    return df.with_columns(pl.Series(column, x))


@pytest.mark.parametrize("case", list(RUNS))
def test_a_bad_run_is_refused(loop, tmp_path, refused, case):
    _copy(loop, tmp_path)
    edit, words = RUNS[case]
    edit(tmp_path)
    refused(_update(), tmp_path, *words)


@pytest.mark.parametrize("gain", ["0", "2", "-0.5", "2.5", "nan", "inf", "half"])
def test_a_gain_out_of_range_is_refused(loop, tmp_path, refused, gain):
    _copy(loop, tmp_path)
    refused(_update("d1.csv", "run1.csv", "d2.csv", "--gain", gain), tmp_path, "gain")


@pytest.mark.parametrize("out", ["d1.csv", "d1.json", "run1.csv", "run1.json", "r.csv",
                                 "r.json", "m.json", "."])
def test_an_output_onto_an_input_or_its_sidecar_is_refused(loop, tmp_path, refused, out):
    _copy(loop, tmp_path)
    refused(_update("d1.csv", "run1.csv", out), tmp_path, out)


def test_an_output_onto_the_previous_drive_in_another_format(loop, tmp_path, refused):
    _copy(loop, tmp_path)
    refused(_update("d1.parquet", "run1.csv", "d1.parquet"), tmp_path, "d1.parquet")
