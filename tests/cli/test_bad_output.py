"""Output-side bad input over every command: one line, exit 2, and no file touched.

Each case points an output of a command at something it must not replace (an input, a
file the user keeps beside the output, a symlink, a FIFO, a device, a read-only file) or
somewhere it cannot write (a missing folder, a file used as a folder, a read-only file
system). The files are built by a fixture; every case asserts the exit code, exactly one
stderr line naming the problem, no traceback, and that every file in the folder (and
the device) is byte-identical afterwards, with no temporary file left behind.
"""

from __future__ import annotations

import json
import os
import re
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from ehss.cli import main
from ehss.io import write_csv

DT = 1e-3
SRC = str(Path(__file__).resolve().parents[2] / "src")


@pytest.fixture
def files(tmp_path, rng, monkeypatch):
    """A working folder with a record, a reference, a model, a parameter file, a run
    file and the kinds of things an output must not replace."""
    monkeypatch.chdir(tmp_path)
    n = 2000
    u = rng.standard_normal(n)
    y = np.zeros(n)
    for k in range(2, n):  # a stable second-order ARX loop
        y[k] = 1.5 * y[k - 1] - 0.7 * y[k - 2] + 0.1 * u[k - 1]
    t = np.arange(n) * DT
    write_csv("data.csv", {"t": t, "u": u, "y": y})
    write_csv("ref.csv", {"t": t, "reference": 1e-4 * np.sin(2 * np.pi * 2 * t)})
    write_csv("run.csv", {"t": t, "reference": u, "output": y})
    Path("model.json").write_text(json.dumps({"a": [1.0, -1.5, 0.7], "b": [0.1],
                                              "c": [1.0], "delay": 1, "dt": DT}))
    Path("p.toml").write_text('name = "mine"\n')
    Path("notes.json").write_text('{"my": "notes"}\n')  # a user's file, not a sidecar
    Path("folder").mkdir()
    Path("folder/kept.txt").write_text("kept\n")
    Path("target.csv").write_text("precious\n")
    os.symlink("target.csv", "link.csv")
    os.symlink("target.csv", "link.json")
    os.symlink("data.csv", "data_link.csv")
    os.link("data.csv", "data_hard.csv")
    os.mkfifo("fifo.csv")
    os.mkfifo("fifo.json")
    Path("ro.csv").write_text("read-only\n")
    Path("ro.json").write_text("read-only\n")
    Path("side.json").write_text("read-only\n")
    for name in ("ro.csv", "ro.json", "side.json"):
        os.chmod(name, 0o444)
    return tmp_path


def _snapshot(root: Path) -> dict[str, tuple]:
    """Kind, mode and content (or link target) of every entry under ``root``."""
    out: dict[str, tuple] = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for name in dirnames + filenames:
            p = Path(dirpath) / name
            st = os.lstat(p)
            if stat.S_ISLNK(st.st_mode):
                body: object = os.readlink(p)
            elif stat.S_ISREG(st.st_mode):
                body = p.read_bytes()
            else:
                body = None
            out[str(p.relative_to(root))] = (stat.S_IFMT(st.st_mode), st.st_mode, st.st_ino,
                                             body)
    return out


IDENTIFY = ["identify", "data.csv", "--input", "u", "--output", "y", "--na", "2", "--nb", "0",
            "--nc", "0"]
FRF = ["frf", "data.csv", "--input", "u", "--output", "y"]
ORDER = ["order", "data.csv", "--input", "u", "--output", "y", "--na", "2", "--nb", "0",
         "--nc", "0"]
SIM = ["simulate", "--loop", "position", "--signal", "sine", "--duration", "0.5"]
SIM_REF = ["simulate", "--loop", "position", "--reference", "ref.csv"]
COMP = ["compensate", "model.json", "ref.csv"]
COMP_UPDATE = ["compensate", "model.json", "ref.csv", "--update", "run.csv"]

# (id, argv, words the one stderr line must hold)
CASES = [
    # an output that is one of the command's inputs
    ("identify-out-is-data", IDENTIFY + ["--out", "data.csv"], "is the input 'data.csv'"),
    ("identify-plot-is-data", IDENTIFY + ["--out", "m.json", "--plot", "data.csv"],
     "is the input"),
    ("frf-out-is-data", FRF + ["--out", "data.csv"], "is the input 'data.csv'"),
    ("frf-out-hard-link-of-data", FRF + ["--out", "data_hard.csv"], "is the input"),
    ("frf-symlinked-input", ["frf", "data_link.csv", "--input", "u", "--output", "y",
                             "--out", "data.csv"], "is the input 'data_link.csv'"),
    ("order-out-is-data", ORDER + ["--out", "data.csv"], "is the input 'data.csv'"),
    ("simulate-out-is-reference", SIM_REF + ["--out", "ref.csv"], "is the input 'ref.csv'"),
    ("simulate-plot-is-params", SIM + ["--params", "p.toml", "--out", "s.csv", "--plot",
                                       "p.toml"], "is the input 'p.toml'"),
    ("compensate-out-is-reference", COMP + ["--out", "ref.csv"], "is the input 'ref.csv'"),
    ("compensate-out-is-run", COMP_UPDATE + ["--out", "run.csv"], "is the input 'run.csv'"),
    ("compensate-sidecar-is-model", COMP + ["--out", "model.csv"],
     "sidecar of 'model.csv') is the input 'model.json'"),
    ("params-save-is-params", ["params", "--params", "p.toml", "--save", "p.toml"],
     "is the input 'p.toml'"),
    ("reproduce-out-is-params", ["reproduce", "--params", "p.toml", "--out", "p.toml"],
     "is the input 'p.toml'"),
    # a JSON sidecar that would replace a file ehss did not write for that table
    ("frf-sidecar-user-file", FRF + ["--out", "notes.csv"], "not the JSON sidecar"),
    ("order-sidecar-user-file", ORDER + ["--out", "notes.csv"], "not the JSON sidecar"),
    ("simulate-sidecar-user-file", SIM + ["--out", "notes.csv"], "not the JSON sidecar"),
    ("compensate-sidecar-user-file", COMP + ["--out", "notes.csv"], "not the JSON sidecar"),
    ("simulate-sidecar-symlink", SIM + ["--out", "link.csv"], "symbolic link"),
    ("simulate-sidecar-fifo", SIM + ["--out", "fifo.parquet", "--plot", "fifo.json"],
     "named pipe"),
    ("frf-sidecar-read-only", FRF + ["--out", "side.csv"], "'side.json': the file is read-only"),
    ("frf-plot-is-sidecar", FRF + ["--out", "f.csv", "--plot", "f.json"],
     "two outputs would be written to one file"),
    ("identify-plot-time-is-out", IDENTIFY + ["--out", "b_time.png", "--plot", "b.png"],
     "two outputs would be written to one file"),
    ("simulate-plot-is-out", SIM + ["--out", "s.csv", "--plot", "s.csv"],
     "two outputs would be written to one file"),
    # a table named .json would be one file with its sidecar; unknown endings
    ("frf-out-json", FRF + ["--out", "x.json"], "a .json name is kept for the table"),
    ("order-out-json", ORDER + ["--out", "x.JSON"], "a .json name is kept for the table"),
    ("simulate-out-json", SIM + ["--out", "notes.json"], "a .json name is kept"),
    ("compensate-out-json", COMP + ["--out", "x.json"], "a .json name is kept"),
    ("simulate-out-unknown-ending", SIM + ["--out", "run.dat"], "unknown ending '.dat'"),
    # things at the output path that a rename would replace
    ("identify-out-symlink", IDENTIFY + ["--out", "link.json"], "symbolic link"),
    ("frf-out-symlink", FRF + ["--out", "link.csv"], "symbolic link"),
    ("compensate-out-fifo", COMP + ["--out", "fifo.csv"], "named pipe"),
    ("identify-out-fifo", IDENTIFY + ["--out", "fifo.json"], "named pipe"),
    ("identify-out-dev-null", IDENTIFY + ["--out", "/dev/null"], "character device"),
    ("params-save-dev-null", ["params", "--save", "/dev/null"], "character device"),
    ("simulate-plot-dev-null", SIM + ["--out", "s.csv", "--plot", "/dev/null"],
     "character device"),
    ("frf-out-dev-null", FRF + ["--out", "/dev/null"], "unknown ending"),
    ("order-out-read-only", ORDER + ["--out", "ro.csv"], "read-only"),
    ("params-save-read-only", ["params", "--save", "ro.json"], "read-only"),
    ("identify-out-folder", IDENTIFY + ["--out", "folder"], "it is a folder"),
    ("params-save-folder", ["params", "--save", "folder"], "it is a folder"),
    # folders that are missing, files, or not writable
    ("identify-missing-folder", IDENTIFY + ["--out", "no/m.json"], "'no' does not exist"),
    ("frf-missing-folder", FRF + ["--out", "no/f.csv"], "'no' does not exist"),
    ("order-missing-folder", ORDER + ["--out", "no/o.csv"], "'no' does not exist"),
    ("simulate-missing-folder", SIM + ["--out", "no/s.csv"], "'no' does not exist"),
    ("compensate-missing-folder", COMP + ["--out", "no/d.csv"], "'no' does not exist"),
    ("params-missing-folder", ["params", "--save", "no/p.toml"], "'no' does not exist"),
    ("simulate-plot-missing-folder", SIM + ["--out", "s.csv", "--plot", "no/s.png"],
     "'no' does not exist"),
    ("frf-folder-is-a-file", FRF + ["--out", "data.csv/f.csv"], "is a file, not a folder"),
    ("identify-folder-is-a-file", IDENTIFY + ["--out", "p.toml/m.json"],
     "is a file, not a folder"),
    # /proc takes no new files, even from root: the probe finds it before the work
    ("simulate-unwritable-folder", SIM + ["--out", "/proc/s.csv"], "is not writable"),
    ("params-unwritable-folder", ["params", "--save", "/proc/p.toml"], "is not writable"),
    ("reproduce-out-is-file", ["reproduce", "--out", "data.csv"], "is not a folder"),
    ("reproduce-missing-parent", ["reproduce", "--out", "no/report"], "'no' does not exist"),
    ("reproduce-unwritable", ["reproduce", "--out", "/proc/report"], "is not writable"),
    ("demo-out-is-file", ["compensate-demo", "--loop", "position", "--out", "data.csv"],
     "is not a folder"),
    ("demo-missing-parent", ["compensate-demo", "--loop", "position", "--out", "no/demo"],
     "'no' does not exist"),
    ("demo-out-fifo", ["compensate-demo", "--loop", "position", "--out", "fifo.csv"],
     "is not a folder"),
]


@pytest.mark.parametrize(("argv", "words"), [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_bad_output_is_one_line_and_touches_nothing(files, capsys, argv, words):
    before = _snapshot(files)
    dev_null = os.stat("/dev/null")
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.count("\n") == 1 and err.endswith("\n"), err
    assert err.startswith(f"ehss {argv[0]}: error: ") and words in err, err
    assert "Traceback" not in err
    assert _snapshot(files) == before  # every file byte-identical, nothing added
    after = os.stat("/dev/null")
    assert stat.S_ISCHR(after.st_mode) and after.st_rdev == dev_null.st_rdev


def test_every_file_argument_is_declared(files):
    """Every argument that names a file uses one of the checked path types, so an
    option added later cannot bypass the output checks."""
    import argparse

    from ehss.cli import build_parser
    from ehss.cli._outputs import InputFile, OutputFile, OutputFolder, OutputTable

    kinds = (InputFile, OutputFile, OutputFolder, OutputTable)
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    assert set(sub.choices) >= {"params", "simulate", "identify", "frf", "order",
                                "compensate", "compensate-demo", "reproduce"}
    import re

    for name, p in sub.choices.items():
        for action in p._actions:
            label = str(action.metavar or "")
            # a file by name (FILE, DIR) or by ending (MODEL.json, run.h5)
            named = "FILE" in label or "DIR" in label or re.search(r"\.[A-Za-z0-9]+$", label)
            if named or action.dest == "data":
                assert action.type in kinds, (name, action.dest)


def test_own_sidecar_is_replaced_and_user_files_kept(files, capsys):
    """A second run replaces the table and the sidecar it wrote itself."""
    assert main(FRF + ["--out", "f.csv"]) == 0
    first = Path("f.json").read_text()
    assert json.loads(first)["ehss_sidecar_of"] == "f.csv"
    Path("f.csv").write_text("stale\n")
    assert main(FRF + ["--nperseg", "512", "--out", "f.csv"]) == 0
    assert Path("f.csv").read_text() != "stale\n"
    assert json.loads(Path("f.json").read_text())["nperseg"] == 512
    # the sidecar of another table is not this table's
    assert main(FRF + ["--out", "f.parquet"]) == 0  # binary: no sidecar
    os.replace("f.json", "g.json")
    assert main(FRF + ["--out", "g.csv"]) == 2
    assert "not the JSON sidecar" in capsys.readouterr().err


def _run(argv, **kwargs):
    env = {**os.environ, "PYTHONPATH": SRC}
    return subprocess.Popen([sys.executable, *argv], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, **kwargs)


def test_import_ehss_is_light():
    """``import ehss.cli`` (what the console script does before it can catch Ctrl-C)
    loads none of the heavy libraries, yet every public name of ehss works."""
    code = ("import sys, ehss, ehss.cli\n"
            "heavy = [m for m in ('numpy', 'scipy', 'numba', 'polars', 'matplotlib', "
            "'argparse') if m in sys.modules]\n"
            "assert not heavy, heavy\n"
            "for name in ehss.__all__:\n"
            "    getattr(ehss, name)\n"
            "from ehss import *\n"
            "print('ok')\n")
    p = _run(["-c", code])
    out, err = p.communicate(timeout=300)
    assert p.returncode == 0, err.decode()
    assert out.decode().strip() == "ok"


@pytest.mark.parametrize("library", ["numpy", "scipy", "numba"])
def test_ctrl_c_while_libraries_load_is_one_line(tmp_path, library):
    """SIGINT arrives while the ``ehss`` entry point imports a heavy library."""
    code = ("import builtins, os, signal, sys\n"
            "real = builtins.__import__\n"
            "def hook(name, *args, **kw):\n"
            f"    if name.split('.')[0] == {library!r}:\n"
            "        builtins.__import__ = real\n"
            "        os.kill(os.getpid(), signal.SIGINT)\n"
            "    return real(name, *args, **kw)\n"
            "builtins.__import__ = hook\n"
            "sys.argv = ['ehss', 'simulate', '--loop', 'position', '--signal', 'sine',\n"
            "            '--out', 'run.csv']\n"
            "from ehss.cli import entry\n"
            "entry()\n")
    p = _run(["-c", code], cwd=tmp_path)
    out, err = p.communicate(timeout=300)
    assert p.returncode == 130, err.decode()
    # before the arguments are parsed the command is not known yet
    assert re.fullmatch(r"ehss( simulate)?: interrupted\n", err.decode()), err.decode()
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_sigterm_mid_write_leaves_no_temporary_file(tmp_path):
    """SIGTERM while the record is being written: exit 143, one line, no file at all."""
    p = _run(["-m", "ehss", "simulate", "--loop", "position", "--signal", "random",
              "--duration", "60", "--out", "big.csv"], cwd=tmp_path)
    deadline = time.monotonic() + 600
    def writing() -> bool:  # the record's temporary file exists and is growing
        return any(f.name.startswith(".big.csv.") and f.stat().st_size > 0
                   for f in tmp_path.iterdir() if f.exists())

    while not writing():
        assert p.poll() is None, p.communicate()[1].decode()
        assert time.monotonic() < deadline
        time.sleep(0.002)
    p.send_signal(signal.SIGTERM)
    out, err = p.communicate(timeout=300)
    assert p.returncode == 128 + signal.SIGTERM, err.decode()
    assert err.decode() == "ehss simulate: terminated\n"
    assert list(tmp_path.iterdir()) == []


class _FullDisk:
    """A file whose writes fail as on a full disk."""

    def __init__(self, fh):
        self._fh = fh

    def write(self, data):
        import errno

        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    def __getattr__(self, name):
        return getattr(self._fh, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self._fh.close()


@pytest.mark.parametrize("ext", ["csv", "parquet", "h5", "npz", "mat"])
def test_full_disk_while_writing_is_one_line_and_leaves_nothing(files, capsys, monkeypatch,
                                                                ext):
    """A write that fails after the checks (the disk fills up) keeps the old files."""
    real_open = open

    def full_open(file, mode="r", *args, **kwargs):
        fh = real_open(file, mode, *args, **kwargs)
        is_output = isinstance(file, (str, Path)) and Path(file).name.startswith(".s.")
        return _FullDisk(fh) if is_output and "w" in mode else fh

    Path("s.json").write_text('{"ehss_sidecar_of": "s.csv", "old": true}\n')
    before = _snapshot(files)
    monkeypatch.setattr("builtins.open", full_open)
    if ext in ("csv", "parquet"):  # polars writes in Rust: fail its write as it reports it
        import polars as pl

        def full(*args, **kwargs):
            raise pl.exceptions.ComputeError("underlying IO error: No space left on device")

        monkeypatch.setattr(pl.DataFrame, f"write_{ext}", full)
    code = main(SIM + ["--out", f"s.{ext}"])
    err = capsys.readouterr().err
    assert code == 1, err
    assert err.count("\n") == 1 and "No space left on device" in err, err
    assert err.startswith(f"ehss simulate: error: cannot write 's.{ext}'"), err
    assert _snapshot(files) == before
