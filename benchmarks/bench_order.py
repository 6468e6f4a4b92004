"""``ehss order`` end to end on a record, against another checkout of ehss, in one run.

Run from the project root, with a baseline tree (e.g. ``git archive 3b7a2e5 src | tar -x
-C /tmp/order-base``) and a record (``ehss reproduce --out /tmp/report`` writes the
report's position record)::

    python benchmarks/bench_order.py /tmp/report/data/position.csv \\
        --against /tmp/order-base/src --rounds 2

Each round runs the command once with this tree's ``src`` and once with the baseline's
(alternating which goes first), each as a fresh process on its own ``PYTHONPATH`` with
its own ``NUMBA_CACHE_DIR``, after one untimed warm-up run of each (numba compiles and
caches its kernels there). Wall-clock seconds and CPU seconds (user + system, of the
process and its threads) of the whole command are printed per run, then the median of
each side and their ratios, and whether both recommended the same orders with the same
simulation fit (the ``best by ...`` line), and whether their order tables are the same
to the last printed digit.
"""

from __future__ import annotations

import argparse
import difflib
import os
import platform
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ARGS = ["--input", "reference", "--output", "output", "--band", "2", "100"]


def _cpu_of_children() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _run(src: Path, record: Path, cache: Path) -> tuple[float, float, str]:
    """(wall seconds, CPU seconds, the recommended orders and their simulation fit,
    followed by the order table as printed) of one ``ehss order`` process."""
    env = {**os.environ, "PYTHONPATH": str(src), "NUMBA_CACHE_DIR": str(cache)}
    t0, c0 = time.perf_counter(), _cpu_of_children()
    out = subprocess.run([sys.executable, "-m", "ehss", "order", str(record), *ARGS],
                         env=env, capture_output=True, text=True, check=True).stdout
    wall, cpu = time.perf_counter() - t0, _cpu_of_children() - c0
    best = " ".join(out[out.index("best by"):].split())
    pick = re.sub(r"\(method.*", "", best).strip()
    fit = re.search(r"simulation fit [-0-9.]+ %", best)
    table = out[: out.index("best by")]
    return wall, cpu, f"{pick} ({fit.group(0) if fit else 'no fit'})\n{table}"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("record", type=Path)
    p.add_argument("--against", type=Path, required=True, help="the baseline's src folder")
    p.add_argument("--rounds", type=int, default=2)
    a = p.parse_args()
    sides = {"this tree": ROOT / "src", "baseline": a.against.resolve()}
    with tempfile.TemporaryDirectory() as tmp:
        caches = {name: Path(tmp) / f"cache{i}" for i, name in enumerate(sides)}
        picks = {name: _run(src, a.record, caches[name])[2] for name, src in sides.items()}
        times: dict[str, list[float]] = {name: [] for name in sides}
        cpus: dict[str, list[float]] = {name: [] for name in sides}
        for r in range(a.rounds):
            order = list(sides) if r % 2 == 0 else list(sides)[::-1]
            for name in order:
                wall, cpu, pick = _run(sides[name], a.record, caches[name])
                times[name].append(wall)
                cpus[name].append(cpu)
                picks[name] = pick
                print(f"round {r + 1}  {name:9s}  {wall:7.1f} s wall  {cpu:7.1f} s CPU   "
                      f"{pick.splitlines()[0]}", flush=True)
    med = {name: statistics.median(v) for name, v in times.items()}
    med_cpu = {name: statistics.median(v) for name, v in cpus.items()}
    print(f"\n{platform.node()} · {os.cpu_count()} cores · Python {platform.python_version()}")
    print(f"load average at the end: {', '.join(f'{x:.1f}' for x in os.getloadavg())}")
    for name, m in med.items():
        print(f"median {name:9s} {m:7.1f} s wall  {med_cpu[name]:7.1f} s CPU")
    print(f"speed-up (baseline / this tree): {med['baseline'] / med['this tree']:.2f}x wall, "
          f"{med_cpu['baseline'] / med_cpu['this tree']:.2f}x CPU")
    first = {name: pick.splitlines()[0] for name, pick in picks.items()}
    print(f"same recommendation: {first['baseline'] == first['this tree']}")
    print(f"same order table: {picks['baseline'] == picks['this tree']}")
    for line in difflib.unified_diff(picks["baseline"].splitlines(),
                                     picks["this tree"].splitlines(), "baseline",
                                     "this tree", n=0, lineterm=""):
        print(line)


if __name__ == "__main__":
    main()
