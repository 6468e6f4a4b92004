"""A second process gives the same results, warnings and errors as this one."""

from __future__ import annotations

import multiprocessing
import os
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

from ehss.errors import EhssWarning, ParameterError
from ehss.experiments import demonstrate
from ehss.experiments.pool import collect, default_jobs, process_pool, submit
from ehss.report.figures import compensation_figure, render_png

SRC = str(Path(__file__).resolve().parents[2] / "src")


@pytest.fixture(scope="module")
def pool():
    with process_pool(2) as executor:
        yield executor


def test_one_job_is_this_process_and_bad_counts_are_refused():
    with process_pool(1) as executor:
        assert executor is None
    with pytest.raises(ParameterError, match="jobs=0 must be at least 1"), process_pool(0):
        pass
    with pytest.raises(TypeError, match="jobs=2.0 must be an integer"), process_pool(2.0):
        pass
    assert 1 <= default_jobs() <= 2


def test_warnings_come_back_and_meet_this_process_filters(pool):
    future = submit(pool, warnings.warn, "drive near its limit", EhssWarning)
    with pytest.warns(EhssWarning, match="drive near its limit"):
        assert collect(future) is None


def test_errors_come_back_as_themselves(pool):
    with pytest.raises(ParameterError, match="loop='valve' must be one of"):
        collect(submit(pool, demonstrate, "valve"))


def test_leaving_by_an_error_stops_the_workers_at_once():
    others = set(multiprocessing.active_children())  # the module's pool, for one
    with pytest.raises(KeyboardInterrupt), process_pool(2) as executor:
        workers = [p for p in multiprocessing.active_children() if p not in others]
        assert len(workers) == 1
        submit(executor, time.sleep, 600.0)
        raise KeyboardInterrupt
    # Awaited, the sleeping worker would still be alive here (for ten minutes). The
    # pool's own thread reaps the stopped worker too: between its waitpid and its
    # recording the exit code, is_alive() here can still answer True, so ask again.
    deadline = time.monotonic() + 60.0
    for process in workers:
        process.join(timeout=60.0)
        while process.is_alive() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not process.is_alive()


@pytest.mark.slow
def test_demonstration_and_its_figure_are_bit_identical_in_a_second_process(pool):
    # The shortest demonstration the function accepts (4 s records, one learning
    # iteration): the claim is that where a part runs changes no bit, whatever its length.
    kw = {"seed": 5, "duration_s": 4.0, "iterations": 1}
    here = demonstrate("position", **kw)
    there = collect(submit(pool, demonstrate, "position", **kw))
    assert there.figures() == here.figures()
    for name in here.references:
        np.testing.assert_array_equal(there.with_.outputs[name], here.with_.outputs[name])
        np.testing.assert_array_equal(there.drives[name], here.drives[name])
    np.testing.assert_array_equal(there.with_.h1, here.with_.h1)
    png_there = collect(submit(pool, render_png, compensation_figure, here))
    assert png_there == render_png(compensation_figure, here)


_ORPHAN_SCRIPT = """
import os, sys, time
from ehss.experiments.pool import process_pool, submit
with process_pool(2) as pool:
    pid = pool.submit(os.getpid).result()
    pool.submit(time.sleep, 120)
    print(pid, flush=True)
    time.sleep(120)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")
def test_a_worker_ends_with_its_parent_even_when_the_parent_is_killed():
    # SIGKILL leaves the parent no clean-up at all: only the kernel can stop the worker
    env = dict(os.environ, PYTHONPATH=SRC + os.pathsep + os.environ.get("PYTHONPATH", ""))
    parent = subprocess.Popen([sys.executable, "-c", _ORPHAN_SCRIPT], env=env,
                              stdout=subprocess.PIPE, text=True)
    try:
        worker = int(parent.stdout.readline())
    finally:
        parent.kill()
        parent.wait(30)
        parent.stdout.close()
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and _alive(worker):
        time.sleep(0.1)
    assert not _alive(worker)


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().split()[2] != "Z"  # a zombie has ended, awaiting its reaper
    except FileNotFoundError:
        return False
