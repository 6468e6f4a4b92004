"""Hostile input to ``ehss live``, run as users run it (``python -m ehss live``).

Every case is refused with exit 2 and one line on stderr naming what is wrong, with no
traceback, and leaves every file of its folder as it was: no report or recording made,
no input or sidecar replaced. Records are two seconds at 500 Hz, replayed as fast as
possible (``--speed inf``); nothing here is paced by the wall clock.
"""

from __future__ import annotations

import socket
from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np
import polars as pl
import pytest

from ehss.io import write_table

FS = 500.0
N = 1000


def _columns() -> dict[str, np.ndarray]:
    t = np.arange(N) / FS
    return {"t": t, "ref1": np.sin(2 * np.pi * 7 * t), "fb1": np.cos(2 * np.pi * 5 * t)}


def _write(path: Path, cols: dict[str, np.ndarray]) -> None:
    suffix = path.suffix
    if suffix == ".csv":
        write_table(path, cols, metadata={})
    elif suffix == ".npz":
        np.savez(path, **cols)
    elif suffix == ".parquet":
        pl.DataFrame(cols).write_parquet(path)
    else:
        with h5py.File(path, "w") as h:
            for name, a in cols.items():
                h[name] = a


def _nan_in_fb(cols: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    cols["fb1"][500:510] = np.nan
    return cols


def _empty(cols: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    return {k: a[:0] for k, a in cols.items()}


def _one_sample(cols: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    return {k: a[:1] for k, a in cols.items()}


FORMATS = [".csv", ".npz", ".parquet", ".h5"]
RECORDS: dict[str, tuple[Callable[[dict], dict], tuple[str, ...]]] = {
    "nan": (_nan_in_fb, ("'fb1'", "row 501")),
    "empty": (_empty, ()),
    "one-sample": (_one_sample, ()),
}


@pytest.mark.parametrize("suffix", FORMATS)
@pytest.mark.parametrize("kind", list(RECORDS))
def test_a_bad_record_is_refused_in_every_format(tmp_path, refused, suffix, kind):
    edit, words = RECORDS[kind]
    _write(tmp_path / f"r{suffix}", edit(_columns()))
    refused(["live", "--replay", f"r{suffix}", "--speed", "inf", "--quiet", "--report",
             "out.json"], tmp_path, f"r{suffix}", *words)


@pytest.mark.parametrize("suffix", [".npz", ".parquet", ".h5"])
def test_a_binary_record_cut_short_is_refused(tmp_path, refused, suffix):
    whole = tmp_path / f"whole{suffix}"
    _write(whole, _columns())
    data = whole.read_bytes()
    whole.unlink()
    (tmp_path / f"r{suffix}").write_bytes(data[: len(data) // 2])
    refused(["live", "--replay", f"r{suffix}", "--speed", "inf", "--quiet"], tmp_path,
            f"r{suffix}")


@pytest.mark.parametrize("suffix", [".npz", ".parquet", ".h5"])
def test_a_text_column_in_a_binary_record_is_refused(tmp_path, refused, suffix):
    cols: dict = _columns()
    cols["ref1"] = np.array([f"{x:.3f}" for x in cols["ref1"]])
    if suffix == ".h5":
        cols["ref1"] = cols["ref1"].astype("S")
    _write(tmp_path / f"r{suffix}", cols)
    refused(["live", "--replay", f"r{suffix}", "--speed", "inf", "--quiet"], tmp_path,
            f"r{suffix}", "'ref1'")


CSV_TEXTS = {
    "no bytes": b"",
    "header only": b"t,ref1,fb1\n",
    "cut mid-row": None,  # the good record with its last row cut in two
    "text in a column": None,
    "binary garbage": bytes(range(256)) * 8,
}


def _csv_text(kind: str) -> bytes:
    rows = [f"{t!r},{r!r},{y!r}" for t, r, y in zip(*_columns().values(), strict=True)]
    if kind == "cut mid-row":
        rows[-1] = rows[-1][: rows[-1].index(",") + 3]
    if kind == "text in a column":
        rows[300] = rows[300].split(",")[0] + ",high,0.5"
    return ("t,ref1,fb1\n" + "\n".join(rows) + "\n").encode()


@pytest.mark.parametrize("kind", list(CSV_TEXTS))
def test_a_malformed_csv_is_refused(tmp_path, refused, kind):
    text = CSV_TEXTS[kind]
    (tmp_path / "r.csv").write_bytes(_csv_text(kind) if text is None else text)
    refused(["live", "--replay", "r.csv", "--speed", "inf", "--quiet"], tmp_path, "r.csv")


@pytest.fixture
def good(tmp_path: Path) -> Path:
    """A good record ``r.csv`` (with its sidecar ``r.json``) in ``tmp_path``."""
    write_table(tmp_path / "r.csv", _columns(), metadata={"units": {"t": "s"}})
    assert (tmp_path / "r.json").exists()
    return tmp_path


REPLAY = ["live", "--replay", "r.csv", "--speed", "inf", "--quiet"]

SETTINGS = {
    "fields unknown": (["--fields", "t,ref1,fb9"], ("fb1",)),
    "fields renamed to nothing": (["--fields", "t=t,ref1=nope,fb1=fb1"], ("nope",)),
    "fields empty": (["--fields", ""], ("--fields",)),
    "fields twice": (["--fields", "t,ref1,ref1"], ("ref1",)),
    "fs zero": (["--fs", "0"], ("fs",)),
    "fs nan": (["--fs", "nan"], ("fs",)),
    "learn beyond the record": (["--learn", "60"], ("--learn", "2 s")),
    "learn negative": (["--learn", "-1"], ("learn",)),
    "band above nyquist": (["--band", "10", "400"], ("250 Hz",)),
    "band reversed": (["--band", "20", "5"], ("band",)),
    "band negative": (["--band", "-5", "20"], ("band",)),
    "band nan": (["--band", "nan", "20"], ("band",)),
    "memory zero": (["--memory", "0"], ("memory",)),
    "memory negative": (["--memory", "-1"], ("memory",)),
    "memory nan": (["--memory", "nan"], ("memory",)),
    "memory inf": (["--memory", "inf"], ("memory",)),
    "forgetting above one": (["--forgetting", "1.5"], ("forgetting",)),
    "u-scale zero": (["--u-scale", "0"], ("u_scale",)),
    "u-scale negative": (["--u-scale", "-2"], ("u_scale",)),
    "u-scale nan": (["--u-scale", "nan"], ("u_scale",)),
    "u-scale inf": (["--u-scale", "inf"], ("u_scale",)),
    "u-scale text": (["--u-scale", "big"], ("--u-scale",)),
    "orders zero": (["--na", "0"], ("na",)),
    "delay negative": (["--delay", "-1"], ("delay",)),
    "p0 zero": (["--p0", "0"], ("p0",)),
    "update zero": (["--update", "0"], ("update",)),
    "speed zero": (["--speed", "0"], ("speed",)),
    "speed negative": (["--speed", "-1"], ("speed",)),
    "rms without compensate": (["--rms", "0.001"], ("--rms",)),
    "event on a replay": (["--event", "1:mass_kg=350"], ("--event",)),
    "compensate on a replay": (["--compensate", "preview"], ("--compensate",)),
    "target without compensate": (["--target", "127.0.0.1:5006"], ("--target",)),
    "stop-after zero": (["--stop-after", "0"], ("stop",)),
    "false alarms zero": (["--false-alarm-hours", "0"], ("false",)),
    "baseline missing": (["--baseline", "none.json"], ("none.json",)),
    "baseline the record": (["--baseline", "r.csv"], ("r.csv",)),
    "dashboard port out of range": (["--dashboard", "70000"], ("70000",)),
}


@pytest.mark.parametrize("case", list(SETTINGS))
def test_settings_that_mean_nothing_are_refused(good, refused, case):
    extra, words = SETTINGS[case]
    refused([*REPLAY, *extra, "--report", "out.json", "--record", "out.h5"], good, *words)


RIG = ["live", "--rig", "position", "--duration", "1", "--speed", "inf", "--quiet"]

RIG_SETTINGS = {
    "event without a colon": (["--event", "mass_kg=350"], ("mass_kg=350",)),
    "event without a value": (["--event", "0.5:mass_kg"], ("0.5:mass_kg",)),
    "event value text": (["--event", "0.5:mass_kg=heavy"], ("heavy",)),
    "event time text": (["--event", "soon:mass_kg=350"], ("soon",)),
    "event time negative": (["--event", "-1:mass_kg=350"], ("--event",)),
    "event time nan": (["--event", "nan:mass_kg=350"], ("nan",)),
    "event after the run": (["--event", "5:mass_kg=350"], ("5",)),
    "event parameter unknown": (["--event", "0.5:wings=2"], ("wings",)),
    "event channel beyond": (["--event", "0.5:mass_kg=350@3"], ("3",)),
    "event channel zero": (["--event", "0.5:mass_kg=350@0"], ("0",)),
    "event value nan": (["--event", "0.5:mass_kg=nan"], ("mass_kg",)),
    "event value negative mass": (["--event", "0.5:mass_kg=-1"], ("mass_kg",)),
    "duration zero": (["--duration", "0"], ("duration",)),
    "duration nan": (["--duration", "nan"], ("duration",)),
    "channels zero": (["--channels", "0"], ("channels",)),
    "channels negative": (["--channels", "-3"], ("channels",)),
    "rms zero": (["--compensate", "causal", "--rms", "0"], ("rms",)),
    "rms negative": (["--compensate", "causal", "--rms", "-1e-3"], ("rms",)),
    "rms nan": (["--compensate", "causal", "--rms", "nan"], ("rms",)),
    "compensate and a target": (["--compensate", "causal", "--target", "127.0.0.1:5006"],
                                ("--target",)),
    "params missing": (["--params", "none.toml"], ("none.toml",)),
}


@pytest.mark.parametrize("case", list(RIG_SETTINGS))
def test_rig_settings_that_mean_nothing_are_refused(tmp_path, refused, case):
    extra, words = RIG_SETTINGS[case]
    refused([*RIG, *extra, "--report", "out.json"], tmp_path, *words)


OUTPUTS = {
    "report onto the record": (["--report", "r.csv"], ("r.csv",)),
    "report onto its sidecar": (["--report", "r.json"], ("r.json",)),
    "record onto the record": (["--record", "r.csv"], ("r.csv",)),
    "record onto its sidecar": (["--record", "r.json"], ("r.json",)),
    "report onto a folder": (["--report", "sub"], ("sub",)),
    "record onto a folder": (["--record", "sub"], ("sub",)),
    "record onto an existing file": (["--record", "old.h5"], ("old.h5",)),
    "report into a missing folder": (["--report", "none/out.json"], ("none",)),
    "record and report the same": (["--record", "o.h5", "--report", "o.h5"], ("o.h5",)),
    "report under a file": (["--report", "r.csv/out.json"], ("r.csv",)),
    "report onto a read-only file": (["--report", "ro.json"], ("ro.json",)),
    "record onto a read-only file": (["--record", "ro.h5"], ("ro.h5",)),
}


@pytest.mark.parametrize("case", list(OUTPUTS))
def test_outputs_never_replace_an_input_or_a_file(good, refused, case):
    (good / "sub").mkdir()
    (good / "sub" / "keep.txt").write_text("kept")
    (good / "old.h5").write_bytes(b"an older recording")
    for name in ("ro.json", "ro.h5"):
        (good / name).write_text("kept")
        (good / name).chmod(0o444)
    extra, words = OUTPUTS[case]
    refused([*REPLAY, *extra], good, *words)


@pytest.mark.parametrize("option", ["--report", "--record"])
def test_outputs_into_a_read_only_folder(good, refused, unwritable_folder, option):
    refused([*REPLAY, option, str(unwritable_folder / "out.h5")], good,
            str(unwritable_folder))


UDP = {
    "no port": "127.0.0.1",
    "port text": "127.0.0.1:port",
    "port out of range": "127.0.0.1:70000",
    "port negative": "127.0.0.1:-1",
    "host unknown": "no-such-host.invalid:5005",
    "host empty": ":5005",
    "host not local": "192.0.2.1:5005",
}


@pytest.mark.parametrize("case", list(UDP))
def test_udp_addresses_that_are_no_address(tmp_path, refused, case):
    address = UDP[case]
    refused(["live", "--udp", address, "--fields", "t,ref1,fb1", "--fs", "1000", "--quiet",
             "--idle-stop", "0.1", "--report", "out.json"], tmp_path, address, timeout=20)


@pytest.mark.parametrize("extra", [["--fs", "1000"], ["--fields", "t,ref1", "--fs", "1000"],
                                   ["--fields", "t,ref1,fb1", "--fs", "0"]])
def test_udp_without_what_it_needs(tmp_path, refused, extra):
    refused(["live", "--udp", "127.0.0.1:0", *extra, "--quiet", "--idle-stop", "0.1",
             "--report", "out.json"], tmp_path, timeout=20)


def test_udp_on_a_busy_port(tmp_path, refused):
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as busy:
        busy.bind(("127.0.0.1", 0))
        port = busy.getsockname()[1]
        refused(["live", "--udp", f"127.0.0.1:{port}", "--fields", "t,ref1,fb1", "--fs",
                 "1000", "--quiet", "--report", "out.json"], tmp_path, str(port), timeout=20)
