"""RELS/RML speed as ratios measured in one run: this tree's kernel against a reference
commit's kernel, a per-sample numpy loop, cold compile and the streaming update.

Run from the project root:  .venv/bin/python benchmarks/bench_rels.py [--quick]
                            [--baseline COMMIT]

The baseline commit's ``src/ehss`` is extracted with ``git archive`` into a temporary
folder and run in a subprocess with its own PYTHONPATH and NUMBA_CACHE_DIR; this
tree's kernel runs in the same kind of subprocess, alternating with it, so that both
see the same machine load. Absolute speeds differ between machines by 3× and more;
the ratios are the figures to compare. Compile time is excluded from throughput and
measured separately in a fresh process with an empty numba cache.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

import numba
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from identification.naive import naive_rels  # noqa: E402

#: one record for everyone: 4th-order ARMAX, RMS-normalised (as rels() runs it)
DATA = """
import numpy as np
from scipy.signal import lfilter
rng = np.random.default_rng(2017)
u = rng.standard_normal(N)
a = np.real(np.poly([0.95 * np.exp(0.1j), 0.95 * np.exp(-0.1j), 0.8, 0.6]))
y = lfilter([0.0, 0.2, 0.1], a, u) + lfilter([1.0, 0.5], a, 0.05 * rng.standard_normal(N))
u, y = u / np.std(u), y / np.std(y)
"""

#: throughput of the batch kernel, best of R runs, for both state layouts
THROUGHPUT = DATA + """
import json, time
from ehss.identification import _kernels as K
import importlib
R = importlib.import_module("ehss.identification.rels")
na, nb, nc, n = 6, 6, 4, 17
out = {}
for method, lam in (("rels", 1.0), ("rels", 0.99), ("rml", 1.0)):
    if hasattr(K, "record"):  # one loop, the estimator in one block, (4, N) records
        def make():
            s = R._settings(na, nb, nc, 1, lam, 1e6, 1e6, n * 1e6, 0.99, method)
            block, _ = R._new_state(s, np.zeros(n))
            def run(uu, yy, e, x):  # e and ξ̂ stay in the record, as rels() reads them
                K.rels_run(block, K.record(uu, yy), np.empty((0, n)), 1, True)
            return run
    elif hasattr(K, "new_block"):  # one loop, the estimator in one block
        def make():
            s = R._settings(na, nb, nc, 1, lam, 1e6, 1e6, n * 1e6, 0.99, method)
            block, _ = R._new_state(s, np.zeros(n))
            return lambda uu, yy, e, x: K.rels_run(block, uu, yy, e, x, np.empty((0, n)),
                                                   1, True)
    elif hasattr(K, "RelsSettings"):  # one step function, typed settings
        def make():
            s = R._settings(na, nb, nc, 1, lam, 1e6, 1e6, n * 1e6, 0.99, method)
            storage, counters, _ = R._new_state(s, np.zeros(n))
            return lambda uu, yy, e, x: K.rels_run(s, storage, counters, uu, yy, e, x,
                                                   np.empty((0, n)), 1)
    else:  # the float-buffer kernel
        def make():
            st = R._new_state(na, nb, nc, 1, lam, 1e6, n * 1e6, 0.99, np.zeros(n), None,
                              method)
            return lambda uu, yy, e, x: K.rels_run(st, uu, yy, e, x, np.empty((0, n)), 1)
    e, x = np.empty(N), np.empty(N)
    make()(u[:10], y[:10], e, x)  # compile (or load from the cache)
    best = np.inf
    for _ in range(R_):
        run = make()
        t0 = time.perf_counter()
        run(u, y, e, x)
        best = min(best, time.perf_counter() - t0)
    out[f"{method} {lam:g}"] = N / best
print(json.dumps(out))
"""

#: cold compile: everything rels() and RelsEstimator need, into an empty cache
COLD = """
import time
t0 = time.perf_counter()
import numpy as np
from ehss.identification.rels import RelsEstimator, rels
t1 = time.perf_counter()
u = np.random.default_rng(0).standard_normal(200)
rels(u, np.roll(u, 1), na=2, nb=1, nc=2)
rels(u, np.roll(u, 1), na=2, nb=1, nc=2, method="rml")
est = RelsEstimator(na=2, nb=1, nc=2)
est.update(0.1, 0.2)
est.update_many(u, u)
print(time.perf_counter() - t1)
"""

STREAM = """
import numpy as np, time
from ehss.identification.rels import RelsEstimator
est = RelsEstimator(na=6, nb=6, nc=4, delay=1, method=METHOD)
rng = np.random.default_rng(1)
u = rng.standard_normal(CALLS).tolist()
y = rng.standard_normal(CALLS).tolist()
est.update(0.1, 0.2)
upd = est.update
pc = time.perf_counter_ns
ts = np.empty(CALLS)
for k in range(CALLS):
    t0 = pc()
    upd(u[k], y[k])
    ts[k] = pc() - t0
print(float(np.median(ts)))
"""


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def run_python(code: str, src: Path, cache: Path) -> str:
    """Run ``code`` in a fresh interpreter with ``src`` first on the path."""
    env = {**os.environ, "PYTHONPATH": str(src), "NUMBA_CACHE_DIR": str(cache)}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                         text=True)
    if out.returncode:
        raise RuntimeError(f"benchmark subprocess failed:\n{out.stderr}")
    return out.stdout.strip().splitlines()[-1]


def extract(commit: str, into: Path) -> Path:
    """``src/ehss`` of ``commit`` (git archive) under ``into``; returns the src folder."""
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", "--format=tar", commit,
                              "src/ehss"], capture_output=True, check=True).stdout
    into.mkdir(parents=True, exist_ok=True)
    tar_path = into / "src.tar"
    tar_path.write_bytes(archive)
    with tarfile.open(tar_path) as tar:
        tar.extractall(into, filter="data")
    return into / "src"


def numpy_rate(n_samples: int, method: str, lam: float) -> float:
    exec_ns: dict = {"N": n_samples}
    exec(DATA, exec_ns)
    u, y = exec_ns["u"], exec_ns["y"]
    t0 = time.perf_counter()
    naive_rels(u, y, na=6, nb=6, nc=4, delay=1, lam=lam, method=method)
    return n_samples / (time.perf_counter() - t0)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--quick", action="store_true", help="fewer samples (smoke run)")
    p.add_argument("--baseline", default="b935c3c", help="commit to compare against")
    p.add_argument("--rounds", type=int, default=3, help="alternating rounds per kernel")
    args = p.parse_args()
    n_big = 10**5 if args.quick else 10**6
    n_numpy = 1_000 if args.quick else 5_000
    repeats = 3 if args.quick else 7
    print(f"machine: nproc={os.cpu_count()}, CPU {cpu_model()}, Python "
          f"{platform.python_version()}, numpy {np.__version__}, numba {numba.__version__}; "
          f"load average {os.getloadavg()[0]:.1f} at the start")
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        trees = {"this tree": ROOT / "src", f"baseline {args.baseline}":
                 extract(args.baseline, tmp / "baseline")}
        cold = {}
        for name, src in trees.items():
            cache = tmp / f"cache-{len(cold)}"
            cache.mkdir()
            cold[name] = float(run_python(COLD, src, cache))  # also fills the cache
        code = f"N = {n_big}\nR_ = {repeats}\n" + THROUGHPUT
        rates: dict[str, list[dict]] = {name: [] for name in trees}
        for _ in range(args.rounds):  # alternate, so that both see the same load
            for i, (name, src) in enumerate(trees.items()):
                rates[name].append(json.loads(run_python(code, src, tmp / f"cache-{i}")))
        stream = {}
        for i, (name, src) in enumerate(trees.items()):
            stream[name] = {m: float(run_python(
                f"CALLS = 100000\nMETHOD = {m!r}\n" + STREAM, src, tmp / f"cache-{i}"))
                for m in ("rels", "rml")}
    this, base = trees
    print()
    print(f"cold compile of the identification kernels (rels + rml, batch + streaming, "
          f"empty cache, fresh process): {this} {cold[this]:.1f} s, {base} "
          f"{cold[base]:.1f} s")
    print()
    print(f"| (6,6,4), {n_big} samples | this tree | {base} | ratio (round by round) | "
          f"numpy loop | × numpy loop |")
    print("|---|---|---|---|---|---|")
    for key in rates[this][0]:
        mine = [r[key] for r in rates[this]]
        theirs = [r[key] for r in rates[base]]
        ratios = [a / b for a, b in zip(mine, theirs, strict=True)]
        method, lam = key.split()
        r_np = numpy_rate(n_numpy, method, float(lam))
        best = max(mine)
        print(f"| {key} | {best / 1e6:.2f} M/s ({1e9 / best:.0f} ns) | "
              f"{max(theirs) / 1e6:.2f} M/s ({1e9 / max(theirs):.0f} ns) | "
              f"{np.median(ratios):.2f} ({', '.join(f'{r:.2f}' for r in ratios)}) | "
              f"{r_np / 1e3:.2f} k/s | {best / r_np:.0f}× |")
    print()
    for name in trees:
        print(f"RelsEstimator.update median, (6,6,4): {name}: "
              f"RELS {stream[name]['rels']:.0f} ns, RML {stream[name]['rml']:.0f} ns")
    print(f"load average {os.getloadavg()[0]:.1f} at the end")


if __name__ == "__main__":
    main()
