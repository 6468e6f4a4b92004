"""Shared fixtures. No data is built at import time.

Numba's on-disk cache is keyed on the source file of each jitted function only, so a
kernel compiled from an older version of a module it uses could be loaded from a
stale cache and pass. The suite therefore compiles into a fresh, empty cache
directory of its own on every run; it is set here, before anything imports numba.
"""

from __future__ import annotations

import os
import shutil
import tempfile

_NUMBA_CACHE = tempfile.mkdtemp(prefix="ehss-numba-cache-")
os.environ["NUMBA_CACHE_DIR"] = _NUMBA_CACHE

import matplotlib  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

matplotlib.use("Agg")


def pytest_unconfigure(config: pytest.Config) -> None:
    """Remove this run's numba cache."""
    shutil.rmtree(_NUMBA_CACHE, ignore_errors=True)


@pytest.fixture
def rng() -> np.random.Generator:
    """A generator with a fixed seed, so every test is reproducible."""
    return np.random.default_rng(20170101)
