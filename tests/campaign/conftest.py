"""A Dask cluster on localhost started as a user starts one, and an archive of tiny records.

The cluster is a ``dask scheduler`` process and ``dask worker`` processes
(``--nworkers 1 --nthreads 1``) on ports they choose, each in a session of its own so that it
can be stopped (or killed) with everything it started; the finaliser stops them all.
The workers import ehss from this source tree (``PYTHONPATH``).
"""

from __future__ import annotations

import datetime as dt
import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

SRC = Path(__file__).resolve().parents[2] / "src"
N_RECORDS = 200
N_SAMPLES = 400
FS_HZ = 1000.0
# a second-order loop, y[k] = 1.2 y[k-1] - 0.5 y[k-2] + 0.2 u[k-1] + 0.1 u[k-2]
A = (1.0, -1.2, 0.5)
B = (0.0, 0.2, 0.1)

MANIFEST = """
records = ["records/*.csv"]
[[channels]]
name = "1"
input = "ref1"
output = "fb1"
[workflow]
orders = [2, 2, 0, 1]
method = "arx"
decimate = "none"
"""


def env() -> dict[str, str]:
    """The environment of every process the tests start: this tree's ehss first."""
    e = dict(os.environ)
    e["PYTHONPATH"] = os.pathsep.join([str(SRC), *filter(None, [e.get("PYTHONPATH")])])
    return e


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start(args: list[str], log: Path) -> subprocess.Popen:
    """A process in a session of its own, its output to ``log``."""
    with open(log, "wb") as fh:
        return subprocess.Popen(args, stdout=fh, stderr=subprocess.STDOUT, env=env(),
                                stdin=subprocess.DEVNULL, start_new_session=True)


def stop(proc: subprocess.Popen, sig: int = signal.SIGTERM) -> None:
    """Stop ``proc`` and every process of its session."""
    if proc.poll() is None:
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            pass
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()


def start_worker(address: str, log: Path, *extra: str) -> subprocess.Popen:
    return start([sys.executable, "-m", "dask", "worker", address, "--nworkers", "1",
                  "--nthreads", "1", "--no-dashboard", *extra], log)


def wait_for_workers(address: str, n: int, timeout_s: float = 60.0) -> None:
    """Block until the scheduler at ``address`` has ``n`` workers."""
    from distributed import Client

    with Client(address, timeout="30s") as client:
        client.wait_for_workers(n, timeout=timeout_s)


def _listening(info: Path, proc: subprocess.Popen, timeout_s: float = 60.0) -> str:
    """The address the scheduler ``proc`` writes to ``info`` once it listens."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if info.exists():
            try:
                return str(json.loads(info.read_text())["address"])
            except (ValueError, KeyError):
                pass   # being written
        if proc.poll() is not None:
            raise RuntimeError(f"the scheduler exited ({proc.returncode}); see its log")
        time.sleep(0.05)
    raise TimeoutError(f"the scheduler wrote no address to {info} in {timeout_s:g} s")


class Cluster:
    """A running scheduler and its workers."""

    def __init__(self, folder: Path, n_workers: int, worker_args: tuple[str, ...] = ()):
        self.folder = folder
        # the scheduler binds ports of its own choosing (0) and writes where it listens:
        # a port found free here may be taken by another test's process before the
        # scheduler binds it ("Address already in use", seen once in seven runs)
        info = folder / "scheduler.json"
        self.procs = [start([sys.executable, "-m", "dask", "scheduler", "--host",
                             "127.0.0.1", "--port", "0", "--dashboard-address",
                             "127.0.0.1:0", "--scheduler-file", str(info)],
                            folder / "scheduler.log")]
        self.address = _listening(info, self.procs[0])
        self.n = 0
        for _ in range(n_workers):
            self.add_worker(*worker_args)

    def add_worker(self, *args: str) -> subprocess.Popen:
        self.n += 1
        p = start_worker(self.address, self.folder / f"worker{self.n}.log", *args)
        self.procs.append(p)
        return p

    def close(self) -> None:
        for p in reversed(self.procs):
            stop(p)


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    """A scheduler and two workers on localhost, stopped when the module's tests end."""
    c = Cluster(tmp_path_factory.mktemp("cluster"), 2)
    try:
        wait_for_workers(c.address, 2)
        yield c
    finally:
        c.close()


def make_archive(folder: Path, n: int = N_RECORDS, seed: int = 0) -> Path:
    """``n`` tiny CSV records of a known loop (``t, ref1, fb1``; a day apart in their
    metadata) and the manifest; returns the manifest."""
    import scipy.signal

    from ehss.io import write_table

    rec = folder / "records"
    rec.mkdir(parents=True)
    rng = np.random.default_rng(seed)
    t = np.arange(N_SAMPLES) / FS_HZ
    day0 = dt.datetime(2026, 1, 1, 8, 0, tzinfo=dt.UTC)
    for i in range(n):
        u = rng.standard_normal(N_SAMPLES)
        y = scipy.signal.lfilter(B, A, u) + 0.01 * rng.standard_normal(N_SAMPLES)
        when = (day0 + dt.timedelta(days=i)).isoformat()
        write_table(rec / f"run{i:03d}.csv", {"t": t, "ref1": u, "fb1": y},
                    {"recorded_at": when})
    manifest = folder / "lab.toml"
    manifest.write_text(MANIFEST)
    return manifest


@pytest.fixture(scope="module")
def archive(tmp_path_factory) -> Path:
    """The manifest of an archive of 200 tiny records."""
    return make_archive(tmp_path_factory.mktemp("archive"))


@pytest.fixture(scope="module")
def reference(archive, tmp_path_factory):
    """The campaign run in this process alone (one worker thread, no cluster)."""
    from ehss.campaign import batch

    out = tmp_path_factory.mktemp("reference")
    return batch(None, out, manifest=archive, workers=0, summary=False)


def run_cli(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "ehss", *args], capture_output=True,
                          text=True, env=env(), timeout=timeout)


def popen_cli(*args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "ehss", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env())


def wait_for_files(folder: Path, n: int, proc: subprocess.Popen,
                   timeout_s: float = 120.0) -> int:
    """Wait until ``folder`` holds ``n`` result files (or ``proc`` ends); their count."""
    deadline = time.monotonic() + timeout_s
    count = 0
    while time.monotonic() < deadline and proc.poll() is None:
        count = len(list(folder.glob("[!.]*.parquet"))) if folder.is_dir() else 0
        if count >= n:
            break
        time.sleep(0.02)
    return count
