"""Independent parts of a programme run in a second process.

The programme's experiments each have their own seed and depend on nothing but the rig
and their settings, and the report's figures only draw finished results, so they can
run side by side on a machine with more than one core. :func:`process_pool` gives the
pool (or ``None`` for one process), :func:`submit` runs a function in it and
:func:`collect` takes its result back, with any warning the function raised raised
again here, where the caller's warning filters judge it as if it had run in this
process.

The results do not depend on where a part ran: each worker process keeps BLAS to one
thread, as the command line does in its own process, so sums are taken in the same
order and the numbers come out the same to the last bit.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import sys
import threading
import warnings
from collections.abc import Callable, Iterator
from concurrent.futures import Executor, Future, ProcessPoolExecutor
from contextlib import contextmanager
from typing import Any, TypeVar

from ehss._checks import check_int
from ehss.errors import ParameterError

__all__ = ["PROGRAMME_STRANDS", "default_jobs", "process_pool", "submit", "collect"]

#: A programme has two long, independent strands (the loop identifications and the
#: compensation demonstrations): more processes than that gain nothing.
PROGRAMME_STRANDS = 2

T = TypeVar("T")

_Caught = list[tuple[Warning | str, type[Warning], str, int]]


def default_jobs() -> int:
    """Processes a programme uses by default: one per strand
    (:data:`PROGRAMME_STRANDS`) the machine has a core for."""
    return max(1, min(PROGRAMME_STRANDS, os.cpu_count() or 1))


def _start_worker() -> None:
    """Worker start-up: BLAS on one thread, as in the calling process (see module doc),
    Ctrl-C ignored (already so from its start, see :func:`process_pool`, unless it
    was started later, from another thread), and an end with the calling process."""
    from threadpoolctl import threadpool_limits

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _end_with_parent()
    threadpool_limits(limits=1, user_api="blas")


def _end_with_parent() -> None:
    """On Linux, have the kernel send this worker SIGTERM when its parent ends.

    The parent stops its workers on its way out, but a second signal during that
    clean-up, or a parent killed outright, would leave a worker running a part whose
    result nobody takes. ``prctl(PR_SET_PDEATHSIG)`` is the kernel's own guarantee; a
    parent that ended before it was set is caught by comparing the parent's pid.
    """
    if not sys.platform.startswith("linux"):
        return
    import ctypes

    parent = multiprocessing.parent_process()
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)
    except (OSError, AttributeError):
        return
    if parent is not None and os.getppid() != parent.pid:
        os._exit(1)


#: ``prctl`` option of linux/prctl.h: the signal a process gets when its parent ends.
_PR_SET_PDEATHSIG = 1


@contextmanager
def process_pool(jobs: int) -> Iterator[Executor | None]:
    """A pool of ``jobs - 1`` worker processes beside this one, or ``None`` for ``jobs=1``.

    Workers are started by ``spawn``, not ``fork``: the calling process may hold
    threads (progress display, BLAS), and a forked copy of a lock held by one of them
    would never be released. They start at once, ignoring Ctrl-C, which is left to the
    calling process: it stops the pool (a worker interrupted on its own would print a
    traceback). On leaving, parts not yet started are cancelled and running ones awaited;
    on leaving by an exception (an error, Ctrl-C), the workers are stopped at once.

    Parameters
    ----------
    jobs : int
        Processes to use, this one included (at least 1).

    Yields
    ------
    Executor or None
        To pass as ``executor`` to :func:`ehss.experiments.run_programme` and
        :func:`ehss.report.write_report`.
    """
    jobs = check_int(jobs, "jobs")
    if jobs < 1:
        raise ParameterError(f"jobs={jobs} must be at least 1")
    if jobs == 1:
        yield None
        return
    pool = ProcessPoolExecutor(
        max_workers=jobs - 1,
        mp_context=multiprocessing.get_context("spawn"),
        initializer=_start_worker,
    )
    others = set(multiprocessing.active_children())
    finished = False
    try:
        _start_ignoring_ctrl_c(pool, jobs - 1)
        yield pool
        finished = True
    finally:
        if not finished:
            # Stopped by an error, Ctrl-C or SIGTERM: the parts already handed to a
            # worker would run on for seconds; their results are not wanted. The workers
            # are the children this pool started, looked up now: one may have started
            # after the pool was made (a signal can arrive at any point of that).
            for process in multiprocessing.active_children():
                if process not in others:
                    process.terminate()
        pool.shutdown(wait=finished, cancel_futures=True)


def _start_ignoring_ctrl_c(pool: ProcessPoolExecutor, workers: int) -> None:
    """Start the workers now, with SIGINT ignored, which a spawned process inherits
    from the moment it starts (a signal handler set later leaves a window open)."""
    if threading.current_thread() is not threading.main_thread():
        return  # signals belong to the main thread; the workers start on first use
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        for _ in range(workers):  # each submit starts a worker while none is idle
            pool.submit(os.getpid)
    finally:
        signal.signal(signal.SIGINT, previous)


def _call_catching(fn: Callable[..., T], args: tuple, kwargs: dict) -> tuple[T, _Caught]:
    """Run ``fn`` in a worker and return its value with every warning it raised."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        value = fn(*args, **kwargs)
    return value, [(w.message, w.category, w.filename, w.lineno) for w in caught]


def submit(executor: Executor, fn: Callable[..., T], /, *args: Any, **kwargs: Any) -> Future:
    """``executor.submit(fn, *args, **kwargs)``, keeping the warnings ``fn`` raises.

    ``fn`` and its arguments must pickle (a module-level function, plain data). Take the
    result with :func:`collect`.
    """
    return executor.submit(_call_catching, fn, args, kwargs)


def collect(future: Future) -> Any:
    """The result of a :func:`submit`: its warnings raised again here, its errors raised."""
    value, caught = future.result()
    for message, category, filename, lineno in caught:
        warnings.warn_explicit(message, category, filename, lineno)
    return value
