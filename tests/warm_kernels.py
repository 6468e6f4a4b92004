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

from ehss import warm_up  # noqa: E402

# the order the suite first needs them: the closed loop, then RELS and RML, batch and
# streaming
warm_up(["simulation", "identification", "streaming"])
