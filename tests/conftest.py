"""Shared fixtures. No data is built at import time.

Numba's on-disk cache is keyed on the source file of each jitted function only, so a
kernel compiled from an older version of a module it uses could be loaded from a
stale cache and pass. The suite therefore compiles into a fresh, empty cache
directory of its own on every run; it is set here, before anything imports numba.

Compiling into an empty cache is about 17 s of the run. A process of its own
(``warm_kernels.py``) compiles the kernels into that cache on the other core while
pytest collects and runs the first tests; it is stopped when the run ends.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

_NUMBA_CACHE = tempfile.mkdtemp(prefix="ehss-numba-cache-")
os.environ["NUMBA_CACHE_DIR"] = _NUMBA_CACHE
_WARM = subprocess.Popen(
    [sys.executable, str(Path(__file__).with_name("warm_kernels.py"))],
    stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, stdin=subprocess.DEVNULL,
)

import matplotlib  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

matplotlib.use("Agg")


def pytest_unconfigure(config: pytest.Config) -> None:
    """Stop the kernel warm-up if it still runs; remove this run's numba cache."""
    _WARM.kill()
    _WARM.wait()
    shutil.rmtree(_NUMBA_CACHE, ignore_errors=True)


@pytest.fixture
def rng() -> np.random.Generator:
    """A generator with a fixed seed, so every test is reproducible."""
    return np.random.default_rng(20170101)
