"""One engine for every campaign: many small tasks on a Dask cluster, one result file each.

A campaign is a list of :class:`Task` objects (a key and a small payload) and one task
function. :func:`run_campaign` sends them to a :mod:`dask.distributed` cluster — a
``LocalCluster`` on this machine by default, or the scheduler at ``tcp://HOST:8786`` — in
a bounded window (:func:`distributed.as_completed`), so the client never holds more than
``window`` futures and, of each finished task, only its key and status. Each worker
writes its task's rows itself, atomically (temporary file + rename), to
``tasks/<key>.parquet``; a task that raises writes one row with the error text to
``tasks/<key>.error.parquet`` instead, and the others go on.

Properties the engine keeps, whatever the scheduling:

- **Reproducible**: a task's random numbers come from its own seed,
  :func:`task_seed` (``numpy.random.SeedSequence`` of the campaign seed and a hash of
  the task key), and every task runs with one BLAS thread, so its rows do not depend
  on the worker, the order or the number of workers.
- **Resumable**: a re-run skips the tasks whose ``<key>.parquet`` exists and retries
  the ones that failed; a worker that dies mid-task leaves at most a temporary file
  (removed on the next run), and Dask runs its task again elsewhere.
- **Nothing lost or duplicated**: one file per key, renamed into place whole; a task
  run twice (a worker lost after it wrote) writes the same bytes onto the same name.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING, Any

import numpy as np

from ehss._files import atomic_path
from ehss.errors import DataError, ParameterError

if TYPE_CHECKING:
    import polars as pl
    from rich.progress import Progress

__all__ = [
    "Task",
    "CampaignRun",
    "task_seed",
    "error_line",
    "run_campaign",
    "read_results",
    "result_files",
    "check_same_campaign",
    "TASKS_FOLDER",
    "DEFAULT_CONNECT_TIMEOUT_S",
]

#: Folder of the per-task result files inside a campaign's output folder.
TASKS_FOLDER = "tasks"
#: How long to wait for an existing scheduler before giving up, s.
DEFAULT_CONNECT_TIMEOUT_S = 5.0
_OK_SUFFIX = ".parquet"
_ERROR_SUFFIX = ".error.parquet"
_STALE_TMP_S = 600.0  # a temporary file this old belongs to no running task


@dataclass(frozen=True)
class Task:
    """One unit of a campaign.

    Attributes
    ----------
    key : str
        Unique within the campaign and safe as a file name (letters, digits, ``-_.``);
        it names the result file and seeds the task's random numbers.
    payload : object
        What the task function needs (paths, parameters); small and picklable.
    labels : dict of str to str
        Columns every row of the task carries, also its error row (e.g. the record).
    """

    key: str
    payload: Any = None
    labels: dict[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        ok = self.key and all(c.isalnum() or c in "-_." for c in self.key)
        if not ok or self.key.startswith("."):
            raise ParameterError(f"task key {self.key!r} must be a non-empty file name of "
                                 "letters, digits, '-', '_' and '.' (not starting with '.')")


@dataclass(frozen=True, kw_only=True)
class CampaignRun:
    """What one call of :func:`run_campaign` did.

    Attributes
    ----------
    n_tasks : int
        Tasks in the campaign.
    n_skipped : int
        Tasks whose result existed from an earlier run.
    n_done, n_failed : int
        Tasks run now that wrote their rows, and that failed (error row written).
    out : Path
        The campaign's folder.
    dashboard : str or None
        The Dask dashboard's address.
    wall_s : float
        Wall time of the run, s.
    """

    n_tasks: int
    n_skipped: int
    n_done: int
    n_failed: int
    out: Path
    dashboard: str | None
    wall_s: float


def task_seed(campaign_seed: int, key: str) -> np.random.SeedSequence:
    """The seed of task ``key``: independent of scheduling, worker and order.

    ``SeedSequence(entropy=campaign_seed, spawn_key=(four 32-bit words of
    SHA-256(key)))``: two keys give statistically independent streams, and the same key
    the same stream in every run.
    """
    digest = hashlib.sha256(key.encode("utf-8")).digest()
    words = tuple(int.from_bytes(digest[i:i + 4], "little") for i in range(0, 16, 4))
    return np.random.SeedSequence(entropy=int(campaign_seed), spawn_key=words)


def error_line(exc: BaseException) -> str:
    """An exception as one line: ``TypeName: message`` (first line of the message)."""
    text = str(exc).strip().splitlines()
    msg = text[0] if text else ""
    name = type(exc).__name__
    return f"{name}: {msg}" if msg else name


# ------------------------------------------------------------------- on the worker


def _write_rows(path: Path, rows: list[dict[str, Any]]) -> None:
    """Write ``rows`` (dicts with the same keys) as one Parquet file, atomically."""
    import polars as pl

    frame = pl.DataFrame(rows, infer_schema_length=None)
    with atomic_path(path) as tmp:
        frame.write_parquet(tmp, statistics=False)


def _error_rows(task: Task, message: str) -> list[dict[str, Any]]:
    return [{"task": task.key, **task.labels, "status": "error", "error": message}]


def execute_task(function: Callable[[Any, np.random.SeedSequence, Path], list[dict]],
                 task: Task, campaign_seed: int, out: str) -> tuple[str, str, str]:
    """Run one task on a worker and write its rows; returns ``(key, status, error)``.

    ``function(payload, seed, out)`` returns the task's rows (a list of dicts, the
    same columns in each); ``out`` is the campaign folder (for files beside the rows,
    such as models). Any exception becomes the task's error row.
    """
    from threadpoolctl import threadpool_limits

    folder = Path(out) / TASKS_FOLDER
    seed = task_seed(campaign_seed, task.key)
    try:
        with threadpool_limits(1):  # one BLAS thread: sums in one order on every worker
            rows = function(task.payload, seed, Path(out))
        rows = [{"task": task.key, **task.labels, "status": "ok", "error": "", **r}
                for r in rows]
        _write_rows(folder / f"{task.key}{_OK_SUFFIX}", rows)
    except Exception as exc:  # noqa: BLE001 - every failure is recorded, the rest go on
        message = error_line(exc)
        _write_rows(folder / f"{task.key}{_ERROR_SUFFIX}", _error_rows(task, message))
        return task.key, "error", message
    with contextlib.suppress(FileNotFoundError):  # an earlier run's failure, now done
        (folder / f"{task.key}{_ERROR_SUFFIX}").unlink()
    return task.key, "ok", ""


# ------------------------------------------------------------------------ client


def _done_keys(folder: Path) -> set[str]:
    """Keys with a result, after removing temporary files a killed run left behind
    (``.<name>.<random>.parquet``, older than any task still writing could make)."""
    done = set()
    now = time.time()
    for entry in os.scandir(folder):
        name = entry.name
        if name.startswith("."):
            with contextlib.suppress(FileNotFoundError):
                if now - entry.stat().st_mtime > _STALE_TMP_S:
                    os.unlink(entry.path)
        elif name.endswith(_OK_SUFFIX) and not name.endswith(_ERROR_SUFFIX):
            done.add(name[: -len(_OK_SUFFIX)])
    return done


@contextlib.contextmanager
def _client(scheduler: str | None, workers: int | None,
            connect_timeout_s: float) -> Iterator[Any]:
    """A ``distributed.Client``: to ``scheduler``, or to a new local cluster."""
    import logging

    import dask
    from distributed import Client, LocalCluster

    if scheduler is None:
        n = max(1, os.cpu_count() or 1) if workers is None else workers
        with LocalCluster(n_workers=max(n, 1), threads_per_worker=1,
                          processes=n > 0, dashboard_address=":0",
                          silence_logs=logging.ERROR) as cluster, Client(cluster) as client:
            yield client
        return
    t = f"{connect_timeout_s:g}s"
    with dask.config.set({"distributed.comm.timeouts.connect": t}):
        try:
            client = Client(scheduler, timeout=t)
        except (OSError, TimeoutError) as exc:
            raise DataError(f"cannot reach the Dask scheduler at {scheduler!r} within "
                            f"{connect_timeout_s:g} s ({error_line(exc)}); start one with "
                            "'dask scheduler' or drop --scheduler for a local cluster") \
                from None
    try:
        yield client
    finally:
        client.close()


def _progress(total: int, skipped: int, quiet: bool) -> Progress:
    """A rich progress bar on stderr (a no-op object when ``quiet``)."""
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    console = Console(stderr=True, quiet=quiet)
    return Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                    TextColumn("{task.fields[failed]} failed"), TimeElapsedColumn(),
                    TimeRemainingColumn(), console=console, transient=False)


def run_campaign(
    function: Callable[[Any, np.random.SeedSequence, Path], list[dict]],
    tasks: Sequence[Task],
    out: str | Path,
    *,
    seed: int = 0,
    scheduler: str | None = None,
    workers: int | None = None,
    window: int | None = None,
    connect_timeout_s: float = DEFAULT_CONNECT_TIMEOUT_S,
    quiet: bool = True,
    description: str = "campaign",
    settings: dict[str, Any] | None = None,
    begin: Callable[[Path], None] | None = None,
) -> CampaignRun:
    """Run ``function`` over ``tasks`` on a Dask cluster; each task writes its own rows.

    Parameters
    ----------
    function : callable ``(payload, seed, out) -> list of dict``
        A module-level function importable on the workers (it is sent by reference).
    tasks : sequence of Task
        Keys must be unique.
    out : str or Path
        Campaign folder (created); the rows go to ``out/tasks/``.
    seed : int, default 0
        Campaign seed; each task's is :func:`task_seed` ``(seed, key)``.
    scheduler : str, optional
        Address of a running scheduler (``tcp://HOST:8786``); default a local cluster.
    workers : int, optional
        Workers of the local cluster (one thread each; default the number of cores;
        0: one worker thread in this process).
    window : int, optional
        Most tasks in flight (default 4 per worker thread, at least 16): bounds the
        client's memory whatever the campaign's size.
    connect_timeout_s : float, default 5
        How long to wait for ``scheduler``.
    quiet : bool, default True
        No progress bar and no dashboard line.
    settings : dict, optional
        What defines the campaign: a folder made with other settings is refused
        (:func:`check_same_campaign`), and the first run records them
        (:func:`record_campaign`) once the cluster is reached.
    begin : callable ``(out) -> None``, optional
        Called once the cluster is reached (after ``settings`` are recorded), before any
        task: writes what else the campaign keeps beside its rows. A scheduler that
        cannot be reached leaves nothing behind.

    Returns
    -------
    CampaignRun

    Raises
    ------
    DataError
        If the scheduler cannot be reached, or ``out`` cannot hold the results.
    ParameterError
        If two tasks share a key, or ``out`` holds a campaign with other settings.
    KeyboardInterrupt
        Passed on after the futures are cancelled; the finished tasks' files stay.
    """
    from distributed import as_completed

    from ehss._checks import check_int, check_real

    if workers is not None:
        check_int(workers, "workers", lo=0)
    check_real(connect_timeout_s, "connect_timeout_s", lo=0.0, lo_open=True, unit="s")
    start = time.perf_counter()
    out = Path(out)
    folder = out / TASKS_FOLDER
    keys = [t.key for t in tasks]
    if len(set(keys)) != len(keys):
        dup = next(k for k in keys if keys.count(k) > 1)
        raise ParameterError(f"task key {dup!r} appears more than once")
    if settings is not None:
        check_same_campaign(out, settings)
    n_done = n_failed = 0
    with _client(scheduler, workers, connect_timeout_s) as client:
        # made once the cluster is reached: a scheduler that cannot be reached leaves
        # no folder behind
        _begin(folder, out, settings, begin)
        done = _done_keys(folder)
        pending = [t for t in tasks if t.key not in done]
        dashboard = client.dashboard_link
        if not quiet:
            print(f"ehss {description}: Dask dashboard at {dashboard}", file=sys.stderr)
        able, unable = _workers_with_ehss(client)
        if not able:  # nothing can run: every task's row says why
            for t in pending:
                _write_rows(folder / f"{t.key}{_ERROR_SUFFIX}", _error_rows(t, unable))
            return CampaignRun(n_tasks=len(tasks), n_skipped=len(tasks) - len(pending),
                               n_done=0, n_failed=len(pending), out=out,
                               dashboard=dashboard, wall_s=time.perf_counter() - start)
        if unable and not quiet:
            print(f"ehss {description}: {unable}; those workers get no tasks",
                  file=sys.stderr)
        threads = sum(n for w, n in client.nthreads().items() if w in able) or 1
        size = window if window is not None else max(16, 4 * threads)
        with _progress(len(tasks), len(tasks) - len(pending), quiet) as bar, \
                _Interrupt() as interrupt:
            bar_id = bar.add_task(description, total=len(tasks),
                                  completed=len(tasks) - len(pending), failed=0)
            queue = iter(pending)
            by_future: dict[Any, Task] = {}
            token = hashlib.sha256(f"{time.time_ns()}{os.getpid()}".encode()).hexdigest()[:8]

            def submit(task: Task) -> Any:
                fut = client.submit(execute_task, function, task, seed, str(out),
                                    key=f"ehss-{task.key}-{token}", pure=False,
                                    workers=able, allow_other_workers=False)
                by_future[fut] = task
                return fut

            # results (key, status, error) come back in batches with the completions,
            # not fetched one round trip per task
            ac = as_completed([submit(t) for t in _take(queue, size)], with_results=True,
                              raise_errors=False)
            try:
                for fut, result in ac:
                    interrupt.check()
                    task = by_future.pop(fut)
                    status = _outcome(fut, result, task, folder)
                    fut.release()
                    n_done += status == "ok"
                    n_failed += status != "ok"
                    bar.update(bar_id, advance=1, failed=n_failed)
                    for nxt in _take(queue, 1):
                        ac.add(submit(nxt))
                interrupt.check()
            except BaseException:
                client.cancel(list(by_future))
                raise
    return CampaignRun(n_tasks=len(tasks), n_skipped=len(tasks) - len(pending),
                       n_done=n_done, n_failed=n_failed, out=out, dashboard=dashboard,
                       wall_s=time.perf_counter() - start)


class _Interrupt:
    """Ctrl-C that is not lost while the campaign waits for its tasks.

    Python ignores an exception raised inside a destructor, and Dask's futures are
    released (``Future.__del__``) in the loop that collects results: a SIGINT that lands
    there would be swallowed and the campaign would run on. Within this context the
    signal is also recorded, and :meth:`check`, called at every completion and after the
    last, raises :class:`KeyboardInterrupt` for one that was swallowed. Outside the main
    thread (where no signal handler can be set) it does nothing.
    """

    def __init__(self) -> None:
        self._seen = threading.Event()
        self._previous: Any = None

    def __enter__(self) -> _Interrupt:
        if threading.current_thread() is threading.main_thread():
            self._previous = signal.getsignal(signal.SIGINT)
            signal.signal(signal.SIGINT, self._handler)
        return self

    def __exit__(self, *exc: object) -> None:
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)

    def _handler(self, signum: int, frame: FrameType | None) -> None:
        self._seen.set()
        if callable(self._previous):
            self._previous(signum, frame)
        else:
            raise KeyboardInterrupt

    def check(self) -> None:
        """Raise :class:`KeyboardInterrupt` if Ctrl-C came and was swallowed."""
        if self._seen.is_set():
            raise KeyboardInterrupt


def _workers_with_ehss(client: Any) -> tuple[list[str], str]:
    """The workers that can import the campaign engine, and a line on those that cannot.

    A worker without ehss would die on the first task sent to it (Dask cannot unpack
    the task's message), so each is asked first, by a function sent by value.
    """
    def probe() -> str:
        import importlib

        importlib.import_module("ehss.campaign.engine")
        return "ok"

    answers = client.run(probe, on_error="return")
    able = sorted(w for w, a in answers.items() if a == "ok")
    bad = {w: a for w, a in answers.items() if a != "ok"}
    if not bad:
        return able, ""
    w, exc = next(iter(sorted(bad.items())))
    why = error_line(exc) if isinstance(exc, BaseException) else str(exc)
    return able, (f"{len(bad)} of {len(answers)} workers cannot import ehss ({w}: {why}); "
                  "install ehss on every worker")


def _take(it: Iterator[Task], n: int) -> list[Task]:
    out = []
    for _ in range(n):
        nxt = next(it, None)
        if nxt is None:
            break
        out.append(nxt)
    return out


def _outcome(fut: Any, result: Any, task: Task, folder: Path) -> str:
    """The task's status; a task that never ran (a worker without ehss, a worker lost
    too often) gets its error row written here, by the client."""
    if fut.status == "finished":
        return result[1]
    exc = result if isinstance(result, BaseException) else fut.exception()
    message = error_line(exc) if exc is not None else f"task {fut.status}"
    missing = _missing_module(exc)
    if missing is not None:
        message = (f"a worker cannot import what the task needs ({error_line(missing)}); "
                   "install ehss on every worker")
    if (folder / f"{task.key}{_OK_SUFFIX}").exists():
        return "ok"  # a run of it on a worker since lost had finished its rows
    _write_rows(folder / f"{task.key}{_ERROR_SUFFIX}", _error_rows(task, message))
    return "error"


def _missing_module(exc: BaseException | None) -> BaseException | None:
    """The ModuleNotFoundError behind ``exc`` (Dask wraps it when it cannot unpack a
    task on a worker), or None."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, ModuleNotFoundError):
            return exc
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return None


def _begin(folder: Path, out: Path, settings: dict[str, Any] | None,
           begin: Callable[[Path], None] | None) -> None:
    """Make the campaign's folder of rows, then record its settings and what ``begin``
    writes beside it."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise DataError(f"cannot create the campaign folder {str(folder)!r}: "
                        f"{exc.strerror or exc}") from None
    if settings is not None:
        record_campaign(out, settings)
    if begin is not None:
        begin(out)


def check_same_campaign(out: str | Path, settings: dict[str, Any]) -> None:
    """Refuse to resume a campaign folder made with other settings.

    ``out/campaign.json`` records the settings of the first run
    (:func:`record_campaign`); a re-run must give the same, or its rows would mix two
    campaigns. Nothing is written here.

    Raises
    ------
    ParameterError
        If ``out`` holds a campaign with other settings (the message names the first
        that differs).
    """
    import json

    from ehss.io import to_jsonable

    path = Path(out) / "campaign.json"
    plain = to_jsonable(settings)
    if not path.exists():
        return
    try:
        old = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise DataError(f"{str(path)!r} is not readable ({error_line(exc)}); move the "
                        "folder aside or use another --out") from None
    if old != plain:
        key = next((k for k in sorted(set(old) | set(plain))
                    if old.get(k) != plain.get(k)), "?")
        raise ParameterError(f"{str(out)!r} holds a campaign with other settings ({key}: "
                             f"{old.get(key)!r} then, {plain.get(key)!r} now); resume it "
                             "with the same settings or use another --out")


def record_campaign(out: str | Path, settings: dict[str, Any]) -> None:
    """Write ``out/campaign.json``, the settings a resumed run must repeat, unless a first
    run wrote it (:func:`check_same_campaign` has compared them)."""
    from ehss.io import to_jsonable, write_json

    path = Path(out) / "campaign.json"
    if not path.exists():
        write_json(path, to_jsonable(settings))


def result_files(out: str | Path) -> list[Path]:
    """The result files of a campaign folder, by key (the rows, then the errors)."""
    folder = Path(out) / TASKS_FOLDER
    if not folder.is_dir():
        return []
    names = sorted(n for n in os.listdir(folder)
                   if n.endswith(_OK_SUFFIX) and not n.startswith("."))
    # A task's rows supersede an error row of the same key: a task whose worker was
    # lost is run again elsewhere, and its first run may still have been recorded as
    # failed by the client while the second one finished.
    ok = {n[: -len(_OK_SUFFIX)] for n in names if not n.endswith(_ERROR_SUFFIX)}
    names = [n for n in names
             if not (n.endswith(_ERROR_SUFFIX) and n[: -len(_ERROR_SUFFIX)] in ok)]
    return [folder / n for n in names]


def read_results(out: str | Path, *, sort_by: Iterable[str] = ("task",)) -> pl.DataFrame:
    """Every row of a campaign folder as one polars DataFrame, sorted by ``sort_by``.

    Rows of failed tasks have ``status == "error"`` and the error text in ``error``;
    their other columns are null.
    """
    import polars as pl

    files = result_files(out)
    if not files:
        return pl.DataFrame({"task": [], "status": [], "error": []},
                            schema={"task": pl.String, "status": pl.String,
                                    "error": pl.String})
    frames = [pl.read_parquet(f) for f in files]
    frame = pl.concat(frames, how="diagonal_relaxed")
    keys = [k for k in sort_by if k in frame.columns]
    return frame.sort(keys, maintain_order=True) if keys else frame
