"""Fitting a grid of candidate structures on the machine's cores, from neighbouring orders.

Each candidate (na, nb, nc, delay) is fitted on a worker thread: the prediction-error
fit spends most of its time in compiled kernels that release the GIL
(:mod:`ehss.identification._pem_kernels`) and in LAPACK, so the threads run side by side;
BLAS is held to one thread each meanwhile, since a multi-threaded BLAS on a loaded machine
spends more time synchronising than computing on these tall, thin least-squares problems.

A candidate with nc ≥ 2 waits for its neighbour with one order less of C (same na, nb,
delay) when the grid has it, and its ARMAX fit is also started from that neighbour's
θ padded with a zero — the start :func:`~ehss.identification.pem.armax_pem` makes
itself with ``smaller_c`` (fitting the neighbour first), so a refit of any candidate
alone gives the same model. The zero-padded neighbour is the neighbour itself, so the
candidate's loss can only be lower than its neighbour's; its other starts win ties.
Which neighbour a candidate waits for depends only on the grid, and each fit only on its
data and starts, so the results do not depend on the number of threads or on which
finishes first; they are handed back in grid order.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Callable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ThreadPoolExecutor, wait

import numpy as np
from threadpoolctl import threadpool_limits

from ehss._checks import check_int
from ehss.errors import EhssWarning
from ehss.identification.model import ArmaxModel

__all__ = ["Candidate", "default_jobs", "check_jobs", "padded_theta", "fit_grid"]

Candidate = tuple[int, int, int, int]  # (na, nb, nc, delay)


def default_jobs() -> int:
    """Threads for a grid search: the cores this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - platforms without affinity
        return max(1, os.cpu_count() or 1)


def check_jobs(jobs: object) -> int:
    """``jobs`` as an int ≥ 1, or :func:`default_jobs` for None."""
    return default_jobs() if jobs is None else check_int(jobs, "jobs", lo=1)


def padded_theta(model: ArmaxModel, na: int, nb: int, nc: int) -> np.ndarray:
    """θ of ``model`` in the layout of orders (na, nb, nc) ≥ its own, zeros added: the
    same model written with more coefficients."""
    theta = np.zeros(na + nb + 1 + nc)
    theta[: model.na] = model.a[1:]
    theta[na : na + model.nb + 1] = model.b
    theta[na + nb + 1 : na + nb + 1 + model.nc] = model.c[1:]
    return theta


def _smaller_neighbours(grid: list[Candidate]) -> list[list[int]]:
    """For each candidate with nc ≥ 2, the grid position of (na, nb, nc − 1, delay)."""
    index = {c: i for i, c in enumerate(grid)}
    out = []
    for na, nb, nc, d in grid:
        near = (na, nb, nc - 1, d)
        out.append([index[near]] if nc >= 2 and near in index else [])
    return out


def _start_from(candidate: Candidate, neighbours: list[ArmaxModel | None]) -> np.ndarray | None:
    """The neighbour's θ padded to the candidate's orders (None if it was not fitted)."""
    fitted = [m for m in neighbours if m is not None]
    return padded_theta(fitted[0], *candidate[:3]) if fitted else None


def fit_grid(
    grid: list[Candidate],
    fit: Callable[[Candidate, np.ndarray | None], ArmaxModel | None],
    *,
    jobs: int,
    neighbours: bool,
) -> Iterator[tuple[int, ArmaxModel | None]]:
    """Fit every candidate of ``grid`` on ``jobs`` threads; yield (position, model) in
    grid order.

    ``fit(candidate, theta0)`` returns the fitted model, or None for a candidate that
    cannot be fitted; ``theta0`` is the padded θ of its neighbour with one order less
    of C (with ``neighbours``, when the grid has it) or None. The unstable-model
    warning of the fits is silenced while the grid runs (the table lists each
    candidate's stability); other warnings pass.
    """
    deps = _smaller_neighbours(grid) if neighbours else [[] for _ in grid]
    models: list[ArmaxModel | None] = [None] * len(grid)
    done = [False] * len(grid)
    submitted = [False] * len(grid)
    running: dict[Future, int] = {}
    given = 0
    with (warnings.catch_warnings(), threadpool_limits(limits=1, user_api="blas"),
          ThreadPoolExecutor(max_workers=jobs) as pool):
        warnings.filterwarnings("ignore", message="identified model is unstable",
                                category=EhssWarning)
        while given < len(grid):
            for i, c in enumerate(grid):
                if not submitted[i] and all(done[j] for j in deps[i]):
                    start = _start_from(c, [models[j] for j in deps[i]]) if deps[i] else None
                    running[pool.submit(fit, c, start)] = i
                    submitted[i] = True
            finished, _ = wait(running, return_when=FIRST_COMPLETED)
            for f in finished:
                i = running.pop(f)
                models[i], done[i] = f.result(), True
            while given < len(grid) and done[given]:
                yield given, models[given]
                given += 1
