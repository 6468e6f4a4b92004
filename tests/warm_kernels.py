"""Compile the suite's numba kernels into this run's cache, on the machine's other core.

``conftest.py`` starts this script in a process of its own when the run begins; while
pytest collects and runs the first tests, it compiles the kernels in the order the suite
first needs them (the closed loop, then RELS and RML, batch and streaming), and the
test processes load them from the run's cache instead of compiling them again. It
checks nothing: a kernel that is not ready when a test needs it is compiled by that
test, as without this script (numba writes its cache files by atomic rename, so
processes sharing a cache do not corrupt it).
"""

from __future__ import annotations

import os

os.nice(10)  # yield to the tests when they need both cores

import numpy as np  # noqa: E402

from ehss import simulate  # noqa: E402
from ehss.identification import RelsEstimator, rels  # noqa: E402

simulate("position", np.zeros(10), seed=0)
u = np.random.default_rng(0).standard_normal(200)
y = np.convolve(u, [0.0, 0.5])[: u.size]
for method in ("rels", "rml"):
    rels(u, y, na=1, nb=0, nc=1, method=method)
estimator = RelsEstimator(na=1, nb=0, nc=1)
estimator.update(0.1, 0.2)
