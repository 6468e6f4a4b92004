"""Shared fixtures. No data is built at import time."""

from __future__ import annotations

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")


@pytest.fixture
def rng() -> np.random.Generator:
    """A generator with a fixed seed, so every test is reproducible."""
    return np.random.default_rng(20170101)
