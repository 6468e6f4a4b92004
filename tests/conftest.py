"""Shared fixtures. No data is built at import time.

Numba's on-disk cache is keyed on the source file of each jitted function only, so a
kernel compiled from an older version of a module it uses could be loaded from a
stale cache and pass. The suite therefore compiles into a fresh, empty cache
directory of its own on every run; it is set here, before anything imports numba.
``make test`` runs the suite in two parts (below) and makes one fresh folder for both,
passed as ``EHSS_TEST_NUMBA_CACHE``; pytest-xdist's workers inherit the folder of the
run that started them.

Compiling into an empty cache is about 17 s of the run. A process of its own
(``warm_kernels.py``) compiles the kernels into that cache on a free core while
pytest collects and runs the first tests; it is stopped when the run ends.

BLAS runs on one thread (unless ``OPENBLAS_NUM_THREADS`` says otherwise), as in
``ehss reproduce``: tests run in parallel processes and start processes of their own,
and idle BLAS threads that spin waiting for work took the cores from them (the part
run by two workers took 120 s instead of 93 s).

``make test`` runs everything but the ``realtime`` tests on every core
(``pytest -n auto``), then the ``realtime`` ones alone: their pacing by the wall clock
must not compete with other tests for the cores.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
_WORKER = "PYTEST_XDIST_WORKER" in os.environ  # inherits the cache of its run
_GIVEN = os.environ.get("EHSS_TEST_NUMBA_CACHE", "")  # made fresh by make test
if not _WORKER:
    _NUMBA_CACHE = _GIVEN or tempfile.mkdtemp(prefix="ehss-numba-cache-")
    os.environ["NUMBA_CACHE_DIR"] = _NUMBA_CACHE
    _WARM_LOG = tempfile.TemporaryFile()  # its error, if it fails
    _WARM = subprocess.Popen(
        [sys.executable, str(Path(__file__).with_name("warm_kernels.py"))],
        stdout=subprocess.DEVNULL, stderr=_WARM_LOG, stdin=subprocess.DEVNULL,
    )

import matplotlib  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

matplotlib.use("Agg")


def pytest_terminal_summary(terminalreporter) -> None:
    """Say so when the kernel warm-up failed (the tests then compiled the kernels)."""
    if _WORKER or _WARM.poll() in (None, 0):
        return
    _WARM_LOG.seek(0)
    lines = _WARM_LOG.read().decode(errors="replace").strip().splitlines() or ["?"]
    terminalreporter.write_line(f"tests/warm_kernels.py failed: {lines[-1]}", yellow=True)


def pytest_unconfigure(config: pytest.Config) -> None:
    """Stop the kernel warm-up if it still runs; remove the run's numba cache (unless
    make test made it: it removes it after both parts)."""
    if _WORKER:
        return
    _WARM.kill()
    _WARM.wait()
    _WARM_LOG.close()
    if not _GIVEN:
        shutil.rmtree(_NUMBA_CACHE, ignore_errors=True)


@pytest.fixture
def rng() -> np.random.Generator:
    """A generator with a fixed seed, so every test is reproducible."""
    return np.random.default_rng(20170101)
