"""RELS/RML throughput: compiled kernel vs per-sample numpy, padasip RLS and SIPPY RLLS ARMAX.

Run from the project root:  .venv/bin/python benchmarks/bench_rels.py [--quick]

Prints a Markdown table (samples/s, ns/sample) and the streaming update median.
Numba compile time is measured separately and excluded from throughput.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
import warnings
from pathlib import Path

import numba
import numpy as np
from scipy.signal import lfilter

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from ehss.identification import _kernels as K  # noqa: E402
from ehss.identification.rels import RelsEstimator, _new_state  # noqa: E402
from identification.naive import naive_rels  # noqa: E402


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def data(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    u = rng.standard_normal(n)
    a = np.real(np.poly([0.95 * np.exp(0.1j), 0.95 * np.exp(-0.1j), 0.8, 0.6]))
    y = lfilter([0.0, 0.2, 0.1], a, u) + lfilter([1.0, 0.5], a, 0.05 * rng.standard_normal(n))
    return u / np.std(u), y / np.std(y)


def kernel_rate(u, y, na, nb, nc, repeats=9, method="rels", lam=1.0) -> tuple[float, float]:
    n = na + nb + 1 + nc
    err, xi = np.empty(u.size), np.empty(u.size)
    hist = np.empty((0, n))
    t0 = time.perf_counter()
    st = _new_state(na, nb, nc, 1, lam, 1e6, n * 1e6, 0.99, np.zeros(n), None, method)
    K.rels_run(st, u[:10], y[:10], err, xi, hist, 1)
    compile_s = time.perf_counter() - t0
    best = np.inf
    for _ in range(repeats):
        st = _new_state(na, nb, nc, 1, lam, 1e6, n * 1e6, 0.99, np.zeros(n), None, method)
        t0 = time.perf_counter()
        K.rels_run(st, u, y, err, xi, hist, 1)
        best = min(best, time.perf_counter() - t0)
    return u.size / best, compile_s


def cold_compile_s() -> float:
    """Compile time of the batch kernel with an empty numba cache (fresh process)."""
    import subprocess
    import tempfile

    code = (
        "import time, numpy as np\n"
        "from ehss.identification import _kernels as K\n"
        "from ehss.identification.rels import _new_state\n"
        "st = _new_state(6, 6, 4, 1, 1.0, 1e6, 17e6, 0.99, np.zeros(17))\n"
        "e = np.empty(4); x = np.empty(4); u = np.zeros(4)\n"
        "t = time.perf_counter(); K.rels_run(st, u, u, e, x, np.empty((0, 17)), 1)\n"
        "print(time.perf_counter() - t)\n"
    )
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache}
        out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                             text=True, check=True)
    return float(out.stdout.strip().splitlines()[-1])


def timed(fn, n_samples: int) -> float:
    t0 = time.perf_counter()
    fn()
    return n_samples / (time.perf_counter() - t0)


def padasip_rate(u, y, na, nb, nc) -> float:
    import padasip as pa

    n = na + nb + 1 + nc
    x = np.column_stack([np.roll(y, i) for i in range(1, n + 1)])  # same regressor size
    f = pa.filters.FilterRLS(n, mu=0.999, w="zeros")
    return timed(lambda: f.run(y, x), y.size)


def _sippy_rls():
    """SIPPY's SISO recursive ARMAX (io_rls.GEN_RLS_id, the ARMAX_mod="RLLS" path).

    SIPPY 1.0.1 fails under numpy >= 2.4 at ``Yp[k] = np.dot(phi.T, teta[:, k]) + eta[k]``
    (a shape-(1,) array assigned to a scalar slot). We load its source unchanged except
    for ``.item()`` on that one line, so the algorithm and its cost are SIPPY's own.
    """
    import importlib.util
    import types

    spec = importlib.util.find_spec("sippy_unipi.io_rls")
    src = Path(spec.origin).read_text()
    bad = "Yp[k] = np.dot(phi.T, teta[:, k]) + eta[k]"
    assert bad in src, "SIPPY source changed; re-check the compatibility patch"
    src = src.replace(bad, "Yp[k] = np.dot(phi.T, teta[:, k]).item() + eta[k]")
    mod = types.ModuleType("sippy_unipi.io_rls_np2")
    mod.__package__ = "sippy_unipi"
    mod.__file__ = spec.origin
    exec(compile(src, spec.origin, "exec"), mod.__dict__)
    return mod.GEN_RLS_id


def sippy_rate(u, y, na, nb, nc) -> float:
    gen_rls_id = _sippy_rls()

    def run():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            # SIPPY counts nb as the number of b coefficients; delay 1
            gen_rls_id("ARMAX", y, u, na, nb + 1, nc, 0, 0, 1, 200)

    return timed(run, y.size)


def streaming_median_ns(na, nb, nc, calls=100_000, method="rels", lam=1.0) -> float:
    est = RelsEstimator(na=na, nb=nb, nc=nc, delay=1, method=method, forgetting=lam)
    rng = np.random.default_rng(1)
    u = rng.standard_normal(calls).tolist()
    y = rng.standard_normal(calls).tolist()
    est.update(0.1, 0.2)
    upd = est.update
    pc = time.perf_counter_ns
    ts = np.empty(calls)
    for k in range(calls):
        t0 = pc()
        upd(u[k], y[k])
        ts[k] = pc() - t0
    return float(np.median(ts))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--quick", action="store_true", help="fewer samples (smoke run)")
    args = p.parse_args()
    rng = np.random.default_rng(2017)
    n_big = 10**5 if args.quick else 10**6
    n_naive = 2_000 if args.quick else 20_000
    n_peer = 2_000 if args.quick else 20_000
    n_sippy = 1_000 if args.quick else 5_000
    u, y = data(n_big, rng)
    print(f"machine: nproc={os.cpu_count()}, CPU {cpu_model()}, Python "
          f"{platform.python_version()}, numpy {np.__version__}, numba {numba.__version__}")
    print()
    print(f"cold compile of the batch kernel (empty cache): {cold_compile_s():.2f} s")
    print()
    print("| method | λ | orders (na,nb,nc) | ehss kernel | cache load | numpy loop | "
          "padasip RLS | SIPPY RLLS | × numpy | × SIPPY | streaming update median |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    runs = (("rels", 1.0, 4, 4, 2), ("rels", 1.0, 6, 6, 4), ("rels", 0.99, 6, 6, 4),
            ("rml", 1.0, 6, 6, 4))
    for method, lam, na, nb, nc in runs:
        rate, comp = kernel_rate(u, y, na, nb, nc, method=method, lam=lam)
        r_np = timed(lambda na=na, nb=nb, nc=nc, method=method, lam=lam: naive_rels(
            u[:n_naive], y[:n_naive], na=na, nb=nb, nc=nc, delay=1, lam=lam, method=method),
            n_naive)
        med = streaming_median_ns(na, nb, nc, method=method, lam=lam)
        if method == "rels" and lam == 1.0:
            r_pa = padasip_rate(u[:n_peer], y[:n_peer], na, nb, nc)
            r_si = sippy_rate(u[:n_sippy], y[:n_sippy], na, nb, nc)
            peers = f"{r_pa / 1e3:.1f} k/s | {r_si / 1e3:.2f} k/s"
            x_si = f"{rate / r_si:.0f}×"
        else:  # no RML in padasip or SIPPY; SIPPY's RLLS has no forgetting factor
            peers, x_si = "— | —", "—"
        print(f"| {method} | {lam:g} | ({na},{nb},{nc}) | {rate / 1e6:.2f} M/s "
              f"({1e9 / rate:.0f} ns) | {comp:.2f} s | {r_np / 1e3:.1f} k/s | {peers} | "
              f"{rate / r_np:.0f}× | {x_si} | {med:.0f} ns |")
    print()
    print(f"samples: kernel {n_big}, numpy loop {n_naive}, padasip {n_peer}, SIPPY {n_sippy}")


if __name__ == "__main__":
    main()
