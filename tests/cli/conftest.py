"""Run the ``ehss`` command as users do, in a process of its own, many times and fast.

A fresh interpreter spends two to three seconds importing numpy, scipy, numba and the
command's modules before it reads its first argument; the hostile-input corpus runs the
command hundreds of times. One interpreter (:data:`_SERVER`) imports them once and then
forks a child per command line: the child runs ``python -m ehss``'s ``__main__`` module
with its own argv, working folder and standard streams (files the test reads), and ends
as the interpreter would (an uncaught exception prints its traceback and exits with 1;
exit handlers run). The exit code is the child's, as the shell would see it.

The server never runs a numba kernel or starts a thread before it forks, so the children
start from a clean state. Where ``fork`` is missing, every command line is a fresh
interpreter instead.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

SRC = str(Path(__file__).resolve().parents[2] / "src")

_SERVER = r"""
import atexit, json, os, runpy, signal, sys, threading, time, traceback
import ehss.cli
for name in ("live", "stream", "compensate", "order", "identify", "frf", "target"):
    __import__(f"ehss.cli._{name}")
import ehss.workflow, ehss.io, ehss.live.session, ehss.live.replay  # what the commands load

def child(job):
    os.chdir(job["cwd"])
    for fd, name, flags in ((0, os.devnull, os.O_RDONLY),
                            (1, job["out"], os.O_WRONLY | os.O_TRUNC),
                            (2, job["err"], os.O_WRONLY | os.O_TRUNC)):
        os.dup2(os.open(name, flags), fd)
    sys.argv = ["ehss", *job["argv"]]
    code = 0
    try:
        runpy.run_module("ehss", run_name="__main__", alter_sys=True)
    except SystemExit as exc:
        if exc.code is None or isinstance(exc.code, int):
            code = exc.code or 0
        else:
            print(exc.code, file=sys.stderr)
            code = 1
    except BaseException:
        traceback.print_exc()
        code = 1
    try:
        threading._shutdown()
        atexit._run_exitfuncs()
        sys.stdout.flush()
        sys.stderr.flush()
    finally:
        os._exit(code)

def wait(pid, timeout):
    end = time.monotonic() + timeout
    while True:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            return os.waitstatus_to_exitcode(status)
        if time.monotonic() > end:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            return "timeout"
        time.sleep(0.005)

print("ready", flush=True)
for line in sys.stdin:
    job = json.loads(line)
    sys.stdout.flush()
    sys.stderr.flush()
    pid = os.fork()
    if pid == 0:
        child(job)
    print(json.dumps({"code": wait(pid, job["timeout"])}), flush=True)
"""


def cli_env(**extra: str) -> dict[str, str]:
    """The environment of a command run by a test: this checkout's ``src`` first."""
    env = dict(os.environ)
    env["PYTHONPATH"] = SRC + os.pathsep + env.get("PYTHONPATH", "")
    env.update(extra)
    return env


@dataclass(frozen=True)
class Run:
    """What a command line did: its exit code and its standard streams."""

    code: int | str
    out: str
    err: str


class _Forker:
    """The server above, fed one command line at a time."""

    def __init__(self) -> None:
        self.proc = subprocess.Popen([sys.executable, "-c", _SERVER], env=cli_env(),
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     text=True)
        assert self.proc.stdout is not None and self.proc.stdout.readline() == "ready\n"
        self.streams = Path(tempfile.mkdtemp(prefix="ehss-cli-streams-"))

    def __call__(self, argv: list[str], cwd: Path, timeout: float) -> Run:
        assert self.proc.stdin is not None and self.proc.stdout is not None
        out, err = self.streams / "out", self.streams / "err"
        out.write_bytes(b"")
        err.write_bytes(b"")
        job = {"argv": argv, "cwd": str(cwd), "out": str(out), "err": str(err),
               "timeout": timeout}
        self.proc.stdin.write(json.dumps(job) + "\n")
        self.proc.stdin.flush()
        code = json.loads(self.proc.stdout.readline())["code"]
        read = lambda p: p.read_bytes().decode("utf-8", "replace")  # noqa: E731
        return Run(code, read(out), read(err))

    def close(self) -> None:
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self.proc.stdin.close()
        self.proc.wait(30)
        self.proc.stdout.close()
        for p in self.streams.iterdir():
            p.unlink()
        self.streams.rmdir()


def _fresh(argv: list[str], cwd: Path, timeout: float) -> Run:
    proc = subprocess.run([sys.executable, "-m", "ehss", *argv], cwd=cwd, env=cli_env(),
                          capture_output=True, timeout=timeout, stdin=subprocess.DEVNULL)
    return Run(proc.returncode, proc.stdout.decode("utf-8", "replace"),
               proc.stderr.decode("utf-8", "replace"))


@pytest.fixture(scope="session")
def ehss_cli() -> Iterator[Callable[..., Run]]:
    """``ehss_cli(argv, cwd, timeout=60)``: run ``python -m ehss *argv`` in ``cwd``."""
    if not hasattr(os, "fork"):
        yield lambda argv, cwd, timeout=60.0: _fresh(argv, cwd, timeout)
        return
    forker = _Forker()
    try:
        yield lambda argv, cwd, timeout=60.0: forker([str(a) for a in argv], cwd, timeout)
    finally:
        forker.close()


def snapshot(folder: Path) -> dict[str, tuple[int, bytes]]:
    """Every file under ``folder`` (recursively): its modification time and bytes."""
    return {str(p.relative_to(folder)): (p.stat().st_mtime_ns, p.read_bytes())
            for p in sorted(folder.rglob("*")) if p.is_file()}


def assert_one_line(err: str, *words: str) -> str:
    """``err`` is exactly one line, no traceback, holding each of ``words``."""
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert "Traceback" not in err, err
    assert len(lines) == 1, err
    for w in words:
        assert w in lines[0], (w, lines[0])
    return lines[0]


@pytest.fixture
def refused(ehss_cli) -> Callable[..., str]:
    """``refused(argv, folder, *words)``: the command run in ``folder`` exits with 2 and
    one line on stderr holding ``words``, without a traceback, and every file under
    ``folder`` is as it was (no file made, changed or removed). Returns the line."""

    def check(argv: list[str], folder: Path, *words: str, timeout: float = 60.0) -> str:
        before = snapshot(folder)
        run = ehss_cli(argv, folder, timeout)
        assert run.code == 2, (run.code, run.err)
        line = assert_one_line(run.err, *words)
        assert snapshot(folder) == before
        return line

    return check


def _creation_denied(folder: Path) -> bool:
    """True if creating a new file in ``folder`` fails for this process."""
    probe = folder / f".ehss-probe-{os.getpid()}"
    try:
        fd = os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except OSError:
        return True
    os.close(fd)
    probe.unlink()
    return False


@pytest.fixture
def unwritable_folder(tmp_path: Path) -> Iterator[Path]:
    """A folder in which this process cannot create a file: a read-only folder of the
    test's own, or, for root (whom file modes do not stop), Linux's ``/sys``, where the
    kernel refuses new files to everyone. Skipped where neither is at hand."""
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    try:
        if _creation_denied(locked):
            yield locked
        elif Path("/sys").is_dir() and _creation_denied(Path("/sys")):
            yield Path("/sys")
        else:
            pytest.skip("no folder here refuses new files to this user")
    finally:
        locked.chmod(0o755)
