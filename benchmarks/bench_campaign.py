"""Campaign engine: speed-up with workers, per-task overhead, throughput, client memory.

Run from the repository root::

    PYTHONPATH=src python benchmarks/bench_campaign.py [--records 200] [--memory 10000]

1. ``ehss.campaign.batch`` over a campaign of ``--records`` synthetic records (1000
   samples each of a known second-order loop, ARMAX (4, 3, 4, 1) by the default
   workflow), on a local cluster of 1 worker and of 2 workers (one thread each), one
   after the other in this run: the ratio of the wall times.
2. Per-task overhead: ``--sleep-tasks`` tasks that each sleep 0.5 s (no CPU, so the
   measure is the engine's: scheduling, serialisation, the result file written and
   renamed) on 1 worker: wall / (n · 0.5 s) − 1.

The clusters of 1-3 are started and warmed up (every worker has imported what the tasks
use) before the timing, which covers the campaign call itself: discovery, submission,
the tasks, and gathering the rows.
3. Throughput: ``--noop-tasks`` tasks that return one row at once, through the engine
   (each writes its Parquet file) and, for comparison, bare ``client.map`` of the same
   function without files, on 2 workers.
4. The client's peak memory on a ``--memory``-task campaign of small synthetic records
   (each task draws 200 samples from its seed and returns their mean and RMS): peak RSS
   of this process (``resource.getrusage``; the local cluster's scheduler runs in it
   too) and the peak of Python's allocations during the run (``tracemalloc``).

Every figure is printed as one JSON line.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import logging
import os
import resource
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

A = (1.0, -1.2, 0.5)
B = (0.0, 0.2, 0.1)


def sleep_task(payload, seed, out):
    time.sleep(payload)
    return [{"slept_s": float(payload)}]


def noop_task(payload, seed, out):
    return [{"value": float(payload)}]


def synthetic_task(payload, seed, out):
    x = np.random.default_rng(seed).standard_normal(200)
    return [{"mean": float(x.mean()), "rms": float(np.sqrt(np.mean(x * x)))}]


def make_records(folder: Path, n: int, n_samples: int = 1000) -> None:
    import scipy.signal

    from ehss.io import write_table

    rng = np.random.default_rng(0)
    t = np.arange(n_samples) / 1000.0
    for i in range(n):
        u = rng.standard_normal(n_samples)
        y = scipy.signal.lfilter(B, A, u) + 0.01 * rng.standard_normal(n_samples)
        write_table(folder / f"r{i:05d}.csv", {"t": t, "ref1": u, "fb1": y}, {})


def report(**kw) -> None:
    print(json.dumps(kw), flush=True)


@contextlib.contextmanager
def local_cluster(n_workers: int):
    """A local cluster of ``n_workers`` one-thread worker processes, warmed up (ehss,
    polars and the workflow imported on every worker) before anything is timed."""
    from distributed import Client, LocalCluster

    with LocalCluster(n_workers=n_workers, threads_per_worker=1, dashboard_address=":0",
                      silence_logs=logging.ERROR) as cluster:
        with Client(cluster) as client:  # closed before the campaign's own client runs
            client.run(_warm)
        yield cluster.scheduler_address, cluster


def _warm() -> None:
    import polars  # noqa: F401

    import ehss.campaign.batch  # noqa: F401
    import ehss.workflow  # noqa: F401


def bench_workers(root: Path, n: int) -> None:
    from ehss.campaign import batch

    rec = root / "records"
    rec.mkdir()
    make_records(rec, n)
    walls = {}
    for workers in (1, 2):
        with local_cluster(workers) as (address, _):
            # first record once, untimed: the identification's first call on each worker
            batch([str(rec / "r00000.csv")], root / f"warm{workers}", scheduler=address,
                  summary=False)
            t0 = time.perf_counter()
            frame = batch([str(rec / "*.csv")], root / f"w{workers}", scheduler=address,
                          summary=False)
            walls[workers] = time.perf_counter() - t0
        assert frame.height == n and (frame["status"] == "ok").all()
    report(bench="workers", records=n, wall_1_worker_s=round(walls[1], 2),
           wall_2_workers_s=round(walls[2], 2), speedup=round(walls[1] / walls[2], 2),
           load_average=os.getloadavg())


def bench_overhead(root: Path, n: int) -> None:
    from ehss.campaign.engine import Task, run_campaign

    with local_cluster(1) as (address, _):
        run_campaign(sleep_task, [Task(f"w{i}", 0.01) for i in range(4)], root / "warm",
                     scheduler=address)
        tasks = [Task(f"s{i:04d}", 0.5) for i in range(n)]
        run = run_campaign(sleep_task, tasks, root / "sleep", scheduler=address)
    ideal = n * 0.5
    report(bench="overhead", tasks=n, task_s=0.5, wall_s=round(run.wall_s, 2),
           per_task_overhead_ms=round(1000 * (run.wall_s - ideal) / n, 1),
           overhead_pct=round(100 * (run.wall_s / ideal - 1), 2),
           load_average=os.getloadavg())


def bench_throughput(root: Path, n: int) -> None:
    from distributed import Client

    from ehss.campaign.engine import Task, run_campaign

    with local_cluster(2) as (address, cluster):
        run_campaign(noop_task, [Task(f"w{i}", i) for i in range(20)], root / "warm2",
                     scheduler=address)
        run = run_campaign(noop_task, [Task(f"n{i:05d}", i) for i in range(n)],
                           root / "noop", scheduler=address)
        with Client(cluster) as client:
            t0 = time.perf_counter()
            futures = client.map(noop_task, range(n), [None] * n, [None] * n, pure=False)
            client.gather(futures)
            bare = time.perf_counter() - t0
    report(bench="throughput", tasks=n, engine_tasks_per_s=round(n / run.wall_s, 1),
           bare_dask_map_tasks_per_s=round(n / bare, 1), load_average=os.getloadavg())


def bench_memory(root: Path, n: int) -> None:
    from ehss.campaign.engine import Task, read_results, run_campaign

    base_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    tracemalloc.start()
    tasks = [Task(f"m{i:05d}", None, {"record": f"synthetic/{i:05d}"}) for i in range(n)]
    run = run_campaign(synthetic_task, tasks, root / "mem", workers=2)
    _, peak_run = tracemalloc.get_traced_memory()
    tracemalloc.reset_peak()
    t0 = time.perf_counter()
    frame = read_results(root / "mem")
    read_s = time.perf_counter() - t0
    _, peak_read = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert frame.height == n
    report(bench="client_memory", tasks=n, wall_s=round(run.wall_s, 1),
           peak_rss_mb=round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
           rss_before_mb=round(base_kb / 1024, 1),
           python_alloc_peak_run_mb=round(peak_run / 2**20, 1),
           python_alloc_peak_read_mb=round(peak_read / 2**20, 1),
           read_results_s=round(read_s, 2))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--records", type=int, default=200)
    p.add_argument("--sleep-tasks", type=int, default=40)
    p.add_argument("--noop-tasks", type=int, default=2000)
    p.add_argument("--memory", type=int, default=10_000)
    p.add_argument("--only", choices=("workers", "overhead", "throughput", "memory"))
    args = p.parse_args()
    report(bench="machine", cpus=os.cpu_count(), load_average=os.getloadavg(),
           python=sys.version.split()[0])
    with tempfile.TemporaryDirectory(prefix="ehss-bench-campaign-") as tmp:
        root = Path(tmp)
        if args.only in (None, "workers"):
            bench_workers(root, args.records)
        if args.only in (None, "overhead"):
            bench_overhead(root, args.sleep_tasks)
        if args.only in (None, "throughput"):
            bench_throughput(root, args.noop_tasks)
        if args.only in (None, "memory"):
            bench_memory(root, args.memory)


if __name__ == "__main__":
    main()
