"""A corpus of bad input files, fed to every command that reads them.

Each case writes a corrupted file into a fresh folder beside valid companions, runs the
command, and checks the promise made to users: exit code 2, exactly one line on stderr
that names the file and the field or column at fault, no traceback, and every file in
the folder byte-identical afterwards (and no new file: no output, no temporary).

Most cases run in-process through :func:`ehss.cli.main`; a few run ``python -m ehss`` in
a subprocess, as users do.
"""

from __future__ import annotations

import functools
import json
import os
import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

import ehss
from ehss.cli import main

FS = 1000.0
N = 2000


# ---------------------------------------------------------------------------- the record
def _record() -> dict[str, np.ndarray]:
    """A small smooth record: t in s, a multisine u (m) and a filtered y (fresh copies)."""
    return {k: v.copy() for k, v in _record_once().items()}


@functools.cache
def _record_once() -> dict[str, np.ndarray]:
    t = np.arange(N) / FS
    u = 1e-3 * (np.sin(2 * np.pi * 2 * t) + 0.5 * np.sin(2 * np.pi * 7 * t)
                + 0.3 * np.sin(2 * np.pi * 13 * t))
    y = np.zeros(N)
    for k in range(2, N):
        y[k] = 1.5 * y[k - 1] - 0.7 * y[k - 2] + 0.1 * u[k - 1] + 0.05 * u[k - 2]
    return {"t": t, "u": u, "y": y}


def _csv(columns: dict[str, np.ndarray], *, header: bool = True, sep: str = ",") -> str:
    names = list(columns)
    rows = np.column_stack([columns[n] for n in names]).tolist()
    lines = [sep.join(names)] if header else []
    lines += [sep.join(map(repr, row)) for row in rows]
    return "\n".join(lines) + "\n"


@functools.cache
def _good(header: bool = True, sep: str = ",") -> str:
    """The valid record as text (built once)."""
    return _csv(_record(), header=header, sep=sep)


def _replace_row(text: str, row: int, new: str) -> str:
    """``text`` with data row ``row`` (1-based, after the header) replaced by ``new``."""
    lines = text.splitlines()
    lines[row] = new
    return "\n".join(lines) + "\n"


def _scaled(s: float) -> str:
    r = _record()
    return _csv({"t": r["t"], "u": r["u"] * s, "y": r["y"] * s})


def _with_time(t: np.ndarray) -> str:
    r = _record()
    return _csv({"t": t, "u": r["u"], "y": r["y"]})


# -------------------------------------------------------------------------- data cases
@dataclass(frozen=True)
class DataCase:
    """A corrupted record file.

    ``content`` is text or bytes (None: the path is made a folder, ``"missing"``: no
    file, ``"under-file"``: the path goes through a regular file); ``cols`` the input and
    output columns asked for; ``expect`` fragments the one stderr line must hold (the file
    name is always checked); ``pair_only``: the case needs two different columns;
    ``names_file``: the fault is in an option, not in the file, so the message need not
    name the file.
    """

    content: Callable[[], str | bytes | None]
    expect: tuple[str, ...]
    cols: tuple[str, str] = ("u", "y")
    name: str = "data.csv"
    extra: tuple[str, ...] = ()
    pair_only: bool = False
    names_file: bool = True


def _big_with_bad_row() -> str:
    """30 000 rows, row 15 000 with a stray field: beyond the first and last hundred."""
    rows = [f"{k / FS!r},0.5,0.25" for k in range(30_000)]
    rows[14_999] = "14.999,1.0,2.0,3.0"
    return "t,u,y\n" + "\n".join(rows) + "\n"


DATA_CASES: dict[str, DataCase] = {
    "missing": DataCase(lambda: "missing", ("no such file",)),
    "folder": DataCase(lambda: None, ("is a folder",)),
    "under-a-file": DataCase(lambda: "under-file", ("cannot read",)),
    "empty": DataCase(lambda: "", ("empty file",)),
    "blank-lines": DataCase(lambda: "\n\n  \n", ("empty file",)),
    "header-only": DataCase(lambda: "t,u,y\n", ("no data rows",)),
    "binary": DataCase(lambda: b"\x00\x01\x02garbage\xff" * 50, ("binary content",)),
    "latin1-cell": DataCase(lambda: _replace_row(_good(), 5, "0.004,\xe9\xff,1.0")
                            .encode("latin-1"), ("column 'u', data row 5", "not a number")),
    "word-in-cell": DataCase(lambda: _replace_row(_good(), 7, "0.006,abc,1.0"),
                             ("column 'u', data row 7", "'abc' is not a number")),
    "empty-cell": DataCase(lambda: _replace_row(_good(), 9, "0.008,,1.0"),
                           ("column 'u', data row 9", "(empty)")),
    "nan-cell": DataCase(lambda: _replace_row(_good(), 11, "0.010,nan,1.0"),
                         ("column 'u'", "non-finite", "data row 11")),
    "inf-cell": DataCase(lambda: _replace_row(_good(), 12, "0.011,-inf,1.0"),
                         ("column 'u'", "non-finite", "data row 12")),
    "huge-cell": DataCase(lambda: _replace_row(_good(), 13, "0.012,1e999,1.0"),
                          ("column 'u'", "non-finite", "data row 13")),
    "short-row": DataCase(lambda: _replace_row(_good(), 100, "0.099,1.0"),
                          ("data row 100 has 2 fields, the header has 3",)),
    "long-row-mid-big-file": DataCase(_big_with_bad_row,
                                      ("data row 15000 has 4 fields, the header has 3",)),
    "duplicate-header": DataCase(lambda: "t,u,u\n0,1,2\n0.001,1,2\n",
                                 ("column name 'u' appears twice",)),
    "empty-header-name": DataCase(lambda: "t,,y\n0,1,2\n0.001,1,2\n",
                                  ("empty name in field 2",)),
    "unknown-column": DataCase(lambda: _good(), ("no column 'v'", "available"),
                               cols=("v", "y")),
    "name-for-headerless": DataCase(lambda: _good(False, " "),
                                    ("no column named 'u'", "no header row", "1 to 3"),
                                    name="data.dat"),
    "column-zero": DataCase(lambda: _good(False, " "),
                            ("there is no column 0", "numbered from 1"), cols=("0", "3"),
                            name="data.dat"),
    "column-beyond": DataCase(lambda: _good(False, " "),
                              ("no column 7; the file has 3 columns",), cols=("7", "3"),
                              name="data.dat"),
    "headerless-no-fs": DataCase(lambda: _good(False, "\t"),
                                 ("no time column", "--fs"), cols=("2", "3"),
                                 name="data.txt"),
    "unknown-suffix": DataCase(lambda: _good(), ("unknown file type '.xyz'",),
                               name="data.xyz"),
    "garbage-mat": DataCase(lambda: b"MATLAB 5.0 MAT-file" + b"\x07" * 200,
                            ("not a readable MATLAB file",), name="data.mat"),
    "garbage-npz": DataCase(lambda: b"PK\x03\x04 not a zip" * 10,
                            ("not a readable .npz file",), name="data.npz"),
    "garbage-h5": DataCase(lambda: b"\x89HDF\r\n\x1a\n" + b"\x00" * 100,
                           ("not a readable HDF5 file",), name="data.h5"),
    "time-repeats": DataCase(lambda: _with_time(np.r_[0.0, np.arange(N - 1) / FS]),
                             ("time column 't' repeats the time 0.0 s at data rows 1 and 2",)),
    "time-backwards": DataCase(lambda: _with_time(np.r_[np.arange(10), 5, np.arange(11, N)]
                                                  / FS),
                               ("time column 't' goes backwards", "data row 10")),
    "time-uneven": DataCase(lambda: _with_time(np.r_[np.arange(500), np.arange(501, N + 1)]
                                               / FS),
                            ("time column 't' jumps", "data row 500", "1 sample(s) missing")),
    "time-step-1e-310": DataCase(lambda: _with_time(np.arange(N) * 1e-310),
                                 ("time column 't'", "step of 1e-310 s", "1e+09 Hz")),
    "time-step-1e300": DataCase(lambda: _with_time(np.arange(N) * 1e300),
                                ("time column 't'", "step of 1e+300 s")),
    "time-unix-seconds": DataCase(lambda: _with_time(1e15 + np.arange(N) / FS),
                                  ("time column 't'", "subtract the start time")),
    "time-nan": DataCase(lambda: _replace_row(_good(), 3, "nan,0,0"),
                         ("column 't'", "non-finite", "data row 3")),
    "fs-disagrees": DataCase(lambda: _good(), ("gives a sample rate of 1000 Hz",
                                                      "--fs is 500 Hz"), extra=("--fs", "500")),
    "fs-zero": DataCase(lambda: _good(), ("fs=0.0", "[1e-09, 1e+09] Hz"),
                        extra=("--fs", "0"), names_file=False),
    "fs-nan": DataCase(lambda: _good(), ("fs=nan",), extra=("--fs", "nan"), names_file=False),
    "fs-huge": DataCase(lambda: _good(), ("fs=1e+20",), extra=("--fs", "1e20"), names_file=False),
    "fs-not-a-number": DataCase(lambda: _good(), ("--fs", "invalid float value: 'abc'"),
                                extra=("--fs", "abc"), names_file=False),
    "fifo": DataCase(lambda: "fifo", ("not a regular file",)),
    "scaled-1e200": DataCase(lambda: _scaled(1e200), ("column 'u' (--input) reaches 1.61e+197",
                                                      "rescale"), pair_only=True),
    "scaled-1e-200": DataCase(lambda: _scaled(1e-200), ("column 'u' (--input) varies by only",
                                                        "rescale"), pair_only=True),
    "constant-output": DataCase(lambda: _csv({**_record(), "y": np.full(N, 3.0)}),
                                ("column 'y' (--output) is constant",), pair_only=True),
    "same-column-by-number": DataCase(lambda: _good(), ("same column 'u'",),
                                      cols=("2", "u"), pair_only=True),
}


def _pair_command(command: str) -> Callable[[Path, Path, DataCase], list[str]]:
    extra = {"identify": ["--na", "2", "--nb", "1", "--nc", "0", "--out", "OUT/m.json"],
             "frf": ["--out", "OUT/frf.csv"],
             "order": ["--na", "1-2", "--nb", "1", "--nc", "0", "--out", "OUT/orders.csv"]}

    def argv(folder: Path, data: Path, case: DataCase) -> list[str]:
        rest = [a.replace("OUT", str(folder)) for a in extra[command]]
        return [command, str(data), "--input", case.cols[0], "--output", case.cols[1],
                *case.extra, *rest]
    return argv


def _simulate(folder: Path, data: Path, case: DataCase) -> list[str]:
    return ["simulate", "--loop", "position", "--reference", str(data), "--column",
            case.cols[0], *case.extra, "--out", str(folder / "run.csv")]


def _compensate(folder: Path, data: Path, case: DataCase) -> list[str]:
    # the valid record does not start or end at rest: the drive fades it in and out
    return ["compensate", str(folder / "model.json"), str(data), "--column", case.cols[0],
            "--fade", "0.05", *case.extra, "--out", str(folder / "drive.csv")]


DATA_COMMANDS = {
    "identify": _pair_command("identify"),
    "frf": _pair_command("frf"),
    "order": _pair_command("order"),
    "simulate": _simulate,
    "compensate": _compensate,
}

_PAIR_COMMANDS = ("identify", "frf", "order")


# --------------------------------------------------------------------------- machinery
def _snapshot(folder: Path) -> dict[str, object]:
    """Every path under ``folder`` with its content: bytes of regular files, the target of
    symbolic links, the mode of folders, pipes and devices (never opened: a pipe would
    block)."""
    out: dict[str, object] = {}
    for p in sorted(folder.rglob("*")):
        key = str(p.relative_to(folder))
        if p.is_symlink():
            out[key] = ("symlink", os.readlink(p))
        elif p.is_file():
            out[key] = (p.stat().st_mode, p.read_bytes())
        else:
            out[key] = ("other", p.stat().st_mode)
    return out


def _good_model(path: Path) -> None:
    path.write_text(json.dumps({"a": [1.0, -1.5, 0.7], "b": [0.1, 0.05], "c": [1.0],
                                "delay": 1, "dt": 1 / FS, "band_hz": [0.0, FS / 4]}))


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    """A working folder with valid companions: a model, a record and a parameter file."""
    _good_model(tmp_path / "model.json")
    (tmp_path / "good.csv").write_text(_good())
    (tmp_path / "rig.toml").write_text("[load]\nmass_kg = 300\n")
    return tmp_path


def _place(folder: Path, name: str, content: str | bytes | None) -> Path:
    path = folder / name
    if content is None:
        path.mkdir()
    elif content == "missing":
        pass
    elif content == "fifo":
        os.mkfifo(path)
    elif content == "under-file":
        (folder / "plain").write_text("x")
        path = folder / "plain" / name
    elif isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content, encoding="utf-8")
    return path


def _check_refused(argv: list[str], folder: Path, capsys, expect: tuple[str, ...],
                   names: tuple[str, ...]) -> None:
    before = _snapshot(folder)
    try:
        code = main(argv)
    except SystemExit as exc:  # argument errors: argparse exits
        code = exc.code
    out, err = capsys.readouterr()
    assert code == 2, f"exit {code}; stderr: {err!r}"
    assert "Traceback" not in out + err
    assert err.endswith("\n") and err.count("\n") == 1, f"not one line: {err!r}"
    for name in names:
        assert name in err, f"{name!r} not named in {err!r}"
    for fragment in expect:
        assert fragment in err, f"{fragment!r} not in {err!r}"
    assert _snapshot(folder) == before, "a file was created, changed or removed"


def _data_params():
    for cname in DATA_CASES:
        for command in DATA_COMMANDS:
            case = DATA_CASES[cname]
            if case.pair_only and command not in _PAIR_COMMANDS:
                continue
            yield pytest.param(cname, command, id=f"{command}-{cname}")


@pytest.mark.parametrize(("case_name", "command"), list(_data_params()))
def test_bad_record_file(folder, capsys, case_name, command):
    case = DATA_CASES[case_name]
    data = _place(folder, case.name, case.content())
    argv = DATA_COMMANDS[command](folder, data, case)
    _check_refused(argv, folder, capsys, case.expect, (case.name,) if case.names_file else ())


# -------------------------------------------------------------------------- model files
_MODEL = {"a": [1.0, -1.5, 0.7], "b": [0.1, 0.05], "c": [1.0], "delay": 1, "dt": 1 / FS}

MODEL_CASES: dict[str, tuple[Callable[[], str | bytes | None], tuple[str, ...]]] = {
    "missing": (lambda: "missing", ("does not exist",)),
    "folder": (lambda: None, ("is a folder",)),
    "under-a-file": (lambda: "under-file", ("cannot read model file",)),
    "fifo": (lambda: "fifo", ("not a regular file",)),
    "empty": (lambda: "", ("is empty",)),
    "not-json": (lambda: "{a: 1", ("is not valid JSON",)),
    "not-utf8": (lambda: json.dumps({**_MODEL, "meta": {"x": "é"}}, ensure_ascii=False)
                 .encode("latin-1"), ("not UTF-8",)),
    "deeply-nested": (lambda: "[" * 200_000 + "]" * 200_000, ("nested too deeply",)),
    "a-list": (lambda: "[1, 2, 3]", ("does not hold a JSON object",)),
    "lacks-b": (lambda: json.dumps({k: v for k, v in _MODEL.items() if k != "b"}),
                ("lacks the field b",)),
    "a-string": (lambda: json.dumps({**_MODEL, "a": "1 -1.5 0.7"}), ("field 'a'",
                                                                      "list of numbers")),
    "a-2d": (lambda: json.dumps({**_MODEL, "a": [[1.0, -1.5, 0.7]]}), ("field 'a'",
                                                                        "flat list")),
    "b-ragged": (lambda: json.dumps({**_MODEL, "b": [0.1, [0.05, 0.0]]}), ("field 'b'",
                                                                            "ragged")),
    "b-number-as-string": (lambda: json.dumps({**_MODEL, "b": ["0.1", 0.05]}),
                           ("field 'b[0]'", "must be a number")),
    "b-null-entry": (lambda: json.dumps({**_MODEL, "b": [None, 0.05]}),
                     ("field 'b[0]'", "must be a number")),
    "b-bool": (lambda: json.dumps({**_MODEL, "b": [True]}), ("field 'b[0]'",)),
    "b-zero": (lambda: json.dumps({**_MODEL, "b": [0.0, 0.0]}), ("field 'b' is all zeros",)),
    "b-empty": (lambda: json.dumps({**_MODEL, "b": []}), ("field 'b' is empty",)),
    "a-not-monic": (lambda: json.dumps({**_MODEL, "a": [2.0, -1.5]}), ("field 'a'",
                                                                        "start with 1")),
    "a-nan": (lambda: json.dumps({**_MODEL, "a": [1.0, float("nan")]}),
              ("field 'a[1]'", "finite")),
    "a-infinity": (lambda: '{"a": [1, Infinity], "b": [1], "delay": 1, "dt": 0.001}',
                   ("field 'a[1]'", "finite")),
    "a-huge-int": (lambda: '{"a": [1, ' + "9" * 400 + '], "b": [1], "delay": 1, "dt": 1}',
                   ("field 'a[1]'", "too large")),
    "a-too-long": (lambda: json.dumps({**_MODEL, "a": [1.0] + [0.0] * 5000}),
                   ("field 'a' has 5001 entries",)),
    "c-string": (lambda: json.dumps({**_MODEL, "c": "1"}), ("field 'c'",)),
    "delay-fraction": (lambda: json.dumps({**_MODEL, "delay": 1.5}), ("field 'delay' = 1.5",)),
    "delay-string": (lambda: json.dumps({**_MODEL, "delay": "2"}), ("field 'delay' = '2'",)),
    "delay-huge": (lambda: json.dumps({**_MODEL, "delay": 10**15}),
                   ("field 'delay' = 1000000000000000",)),
    "delay-negative": (lambda: json.dumps({**_MODEL, "delay": -3}), ("field 'delay' = -3",)),
    "delay-bool": (lambda: json.dumps({**_MODEL, "delay": True}), ("field 'delay' = True",)),
    "dt-string": (lambda: json.dumps({**_MODEL, "dt": "0.001"}), ("field 'dt' = '0.001'",)),
    "dt-zero": (lambda: json.dumps({**_MODEL, "dt": 0}), ("field 'dt' = 0.0",)),
    "dt-subnormal": (lambda: json.dumps({**_MODEL, "dt": 1e-310}), ("field 'dt'",)),
    "noise-variance-negative": (lambda: json.dumps({**_MODEL, "noise_variance": -1}),
                                ("field 'noise_variance'",)),
    "covariance-ragged": (lambda: json.dumps({**_MODEL, "covariance": [[1.0, 0.0], [1.0]]}),
                          ("field 'covariance'",)),
    "meta-list": (lambda: json.dumps({**_MODEL, "meta": [1, 2]}), ("field 'meta'",)),
    "offsets-list": (lambda: json.dumps({**_MODEL, "offsets": [1.0, 2.0]}),
                     ("field 'offsets'",)),
    "offsets-string": (lambda: json.dumps({**_MODEL, "offsets": {"input": "1",
                                                                 "output": 0.0}}),
                       ("field 'offsets.input'",)),
    "band-reversed": (lambda: json.dumps({**_MODEL, "band_hz": [50.0, 1.0]}),
                      ("field 'band_hz'",)),
    "band-above-nyquist": (lambda: json.dumps({**_MODEL, "band_hz": [1.0, 900.0]}),
                           ("field 'band_hz'", "fs/2 = 500 Hz")),
    "known-not-object": (lambda: json.dumps({**_MODEL, "meta": {"known_factors": [1, 2]}}),
                         ("field 'meta.known_factors'",)),
    "known-string-coefficient": (lambda: json.dumps(
        {**_MODEL, "meta": {"known_factors": {"num": ["1"], "den": [1.0]}}}),
        ("field 'meta.known_factors.num[0]'",)),
    "known-unstable": (lambda: json.dumps(
        {**_MODEL, "meta": {"known_factors": {"num": [1.0], "den": [1.0, -1.5]}}}),
        ("field 'meta.known_factors'", "unit circle")),
    "known-not-a-factor": (lambda: json.dumps(
        {**_MODEL, "meta": {"known_factors": {"num": [1.0, -0.99], "den": [1.0]}}}),
        ("field 'meta.known_factors'", "does not divide the model's 'b'")),
}


@pytest.mark.parametrize("case_name", list(MODEL_CASES))
def test_bad_model_file(folder, capsys, case_name):
    content, expect = MODEL_CASES[case_name]
    model = _place(folder, "bad_model.json", content())
    argv = ["compensate", str(model), str(folder / "good.csv"), "--column", "u",
            "--out", str(folder / "drive.csv")]
    _check_refused(argv, folder, capsys, ("model file",) + expect, ("bad_model.json",))


# --------------------------------------------------------------------- parameter files
PARAM_CASES: dict[str, tuple[Callable[[], str | bytes | None], tuple[str, ...]]] = {
    "missing": (lambda: "missing", ("does not exist",)),
    "folder": (lambda: None, ("is a folder",)),
    "under-a-file": (lambda: "under-file", ("cannot read",)),
    "fifo": (lambda: "fifo", ("not a regular file",)),
    "not-utf8": (lambda: "[load]\nmass_kg = 250 # é\n".encode("latin-1"), ("not UTF-8",)),
    "not-toml": (lambda: "[load\nmass_kg = 1\n", ("not valid TOML",)),
    "deeply-nested": (lambda: "x = " + "[" * 10_000 + "]" * 10_000 + "\n",
                      ("parameter file",)),
    "bool-as-string": (lambda: '[valve]\nsaturate = "no"\n',
                       ("valve.saturate='no'", "true or false")),
    "bool-as-int": (lambda: "[sensors]\nquantize = 0\n", ("sensors.quantize=0",)),
    "number-as-string": (lambda: '[load]\nmass_kg = "250"\n', ("load.mass_kg='250'",)),
    "int-as-float": (lambda: "[sensors]\nadc_bits = 16.5\n", ("sensors.adc_bits=16.5",)),
    "rate-absurd": (lambda: "[timing]\ninternal_rate_hz = 1e9\n",
                    ("timing.internal_rate_hz", "[1, 1e+06] Hz")),
    "substeps-absurd": (lambda: "[timing]\ncontrol_rate_hz = 10\ninternal_rate_hz = 100000\n",
                        ("[timing]", "at most 1000 plant steps")),
    "mass-absurd": (lambda: "[load]\nmass_kg = 1e12\n", ("load.mass_kg", "[0.001, 1e+07] kg")),
    "mass-negative": (lambda: "[load]\nmass_kg = -5\n", ("load.mass_kg=-5",)),
    "mass-nan": (lambda: "[load]\nmass_kg = nan\n", ("load.mass_kg=nan", "finite")),
    "mass-huge-int": (lambda: "[load]\nmass_kg = 1" + "0" * 400 + "\n",
                      ("load.mass_kg", "too large")),
    "unknown-key": (lambda: "[load]\nmas_kg = 300\n", ("unknown parameter load.mas_kg",)),
    "unknown-section": (lambda: "[lod]\nmass_kg = 300\n", ("unknown parameter section 'lod'",)),
    "section-not-table": (lambda: "load = 3\n", ("[load] must be a table",)),
    "preset-number": (lambda: "preset = 1\n", ("preset=1",)),
    "preset-unknown": (lambda: 'preset = "nope"\n', ("unknown preset 'nope'",)),
}


def _params_argv(command: str, folder: Path, path: Path) -> list[str]:
    if command == "params":
        return ["params", "--params", str(path)]
    return ["simulate", "--loop", "position", "--signal", "sine", "--duration", "0.1",
            "--params", str(path), "--out", str(folder / "run.csv")]


@pytest.mark.parametrize("command", ["params", "simulate"])
@pytest.mark.parametrize("case_name", list(PARAM_CASES))
def test_bad_parameter_file(folder, capsys, case_name, command):
    content, expect = PARAM_CASES[case_name]
    path = _place(folder, "bad.toml", content())
    _check_refused(_params_argv(command, folder, path), folder, capsys, expect, ("bad.toml",))


@pytest.mark.parametrize(
    ("where", "expect"),
    [
        ("missing/p.toml", ("folder", "does not exist")),
        ("sub", ("it is a folder",)),
        ("readonly.toml", ("read-only",)),
        ("rig.toml", ("is the input", "would replace the input")),
        ("link.toml", ("symbolic link",)),
        ("pipe.toml", ("named pipe",)),
    ],
)
def test_params_save_refused(folder, capsys, where, expect):
    (folder / "sub").mkdir()
    (folder / "other.toml").write_text("[load]\nmass_kg = 400\n")
    (folder / "link.toml").symlink_to(folder / "other.toml")
    os.mkfifo(folder / "pipe.toml")
    ro = folder / "readonly.toml"
    ro.write_text("# keep me\n")
    ro.chmod(0o444)
    argv = ["params", "--params", str(folder / "rig.toml"), "--save", str(folder / where)]
    _check_refused(argv, folder, capsys, expect, (Path(where).name,))


# -------------------------------------------------------------------- positive controls
@pytest.mark.parametrize("command", list(DATA_COMMANDS))
def test_the_valid_companions_are_accepted(folder, capsys, command):
    """The corpus fails because of its corruption: the same command on the valid record
    and model succeeds."""
    case = DataCase(lambda: "", ())
    argv = DATA_COMMANDS[command](folder, folder / "good.csv", case)
    assert main(argv) == 0, capsys.readouterr().err
    assert main(["params", "--params", str(folder / "rig.toml")]) == 0


def test_headerless_record_by_number_is_accepted(folder, capsys):
    data = folder / "dryer.dat"
    data.write_text(_csv(_record(), header=False, sep="   "))
    out = folder / "frf.csv"
    assert main(["frf", str(data), "--input", "2", "--output", "3", "--time-column", "1",
                 "--out", str(out)]) == 0
    assert out.exists()


# ---------------------------------------------------------------- through a subprocess
def _ehss(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    src = str(Path(ehss.__file__).resolve().parents[1])
    env = {**os.environ, "PYTHONPATH": src + os.pathsep + os.environ.get("PYTHONPATH", "")}
    return subprocess.run([sys.executable, "-m", "ehss", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize(
    ("argv", "content", "name", "expect"),
    [
        (["compensate", "m.json", "good.csv", "--column", "u", "--out", "d.csv"],
         '{"a": [1], "b": [1], "delay": 0.5, "dt": 1}', "m.json", "field 'delay' = 0.5"),
        (["identify", "big.csv", "--input", "u", "--output", "y", "--na", "2", "--nb", "1",
          "--nc", "0", "--out", "m2.json"], None, "big.csv", "data row 15000 has 4 fields"),
    ],
)
def test_bad_input_through_the_command_line(folder, argv, content, name, expect):
    if content is None:
        content = _big_with_bad_row()
    _place(folder, name, content)
    before = _snapshot(folder)
    proc = _ehss(*argv, cwd=folder)
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stdout + proc.stderr
    assert proc.stderr.count("\n") == 1 and name in proc.stderr and expect in proc.stderr
    assert _snapshot(folder) == before
