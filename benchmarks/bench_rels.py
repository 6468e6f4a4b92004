"""RELS/RML speed as ratios measured in one process: this tree's kernels (the one
specialised to the orders, the generic one, the many-channel bank) against the kernels
of earlier commits loaded from git into the same process, plus cold compile, first
use of new orders and the streaming update.

Run from the project root:  .venv/bin/python benchmarks/bench_rels.py [--quick]
                            [--rounds R] [--lanes | --compile]

``--compile`` runs only the cold compile, in R alternating rounds. ``--lanes`` runs
only the P pass of a bank of (4,3,4) channels in each layout (one
channel at a time; channels in SIMD lanes with a run-time lane count; the lanes with
each row's (j, c) update as one loop), with and without FMA contraction, against the
whole step of the bank and of eight single-channel runs of the baseline.

The earlier kernels are read with ``git show COMMIT:src/ehss/identification/…`` into a
temporary package and imported next to this tree's, so that every kernel runs in the
same process, in alternating rounds, under the same machine load. 3b7a2e5 is the
one-entry kernel this work started from; b935c3c the float-buffer kernel with the P
pass in generated LLVM IR (its ``_simd.py`` comes along). Times are the CPU time of
the running thread (``time.thread_time``: a run that the scheduler pauses on a shared
machine is not charged for the pause), the best of several runs; the ratios are the
figures to compare. Compile times are measured in fresh processes with empty numba
caches, as CPU and wall seconds.
"""

from __future__ import annotations

import argparse
import importlib
import os
import platform
import subprocess
import sys
import tarfile
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numba
import numpy as np
from numba import njit
from scipy.signal import lfilter

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from ehss.identification import _bank_kernels as B  # noqa: E402
from ehss.identification import _kernels as K  # noqa: E402
from ehss.identification._common import RelsSettings, new_state, start_state  # noqa: E402
from ehss.identification.bank import RelsBank  # noqa: E402
from ehss.identification.rels import RelsEstimator  # noqa: E402

R = importlib.import_module("ehss.identification.rels")

BASELINE = "3b7a2e5"
IR_KERNEL = "b935c3c"
VARIANTS = (("rels", 1.0), ("rels", 0.99), ("rml", 1.0))
COMPILE_ROUNDS = 3


def record_of(n_samples: int, n_channels: int = 1,
              seed: int = 2017) -> tuple[np.ndarray, np.ndarray]:
    """u, y of a 4th-order ARMAX loop, RMS-normalised (as rels() runs them); (N,) or
    (N, C) with independent channels."""
    rng = np.random.default_rng(seed)
    u = rng.standard_normal((n_samples, n_channels))
    a = np.real(np.poly([0.95 * np.exp(0.1j), 0.95 * np.exp(-0.1j), 0.8, 0.6]))
    noise = 0.05 * rng.standard_normal(u.shape)
    y = lfilter([0.0, 0.2, 0.1], a, u, axis=0) + lfilter([1.0, 0.5], a, noise, axis=0)
    u, y = u / u.std(axis=0), y / y.std(axis=0)
    return (u[:, 0].copy(), y[:, 0].copy()) if n_channels == 1 else (u, y)


# ---------------------------------------------------------------- the kernels
def git_show(commit: str, path: str) -> str:
    return subprocess.run(["git", "-C", str(ROOT), "show", f"{commit}:{path}"],
                          capture_output=True, text=True, check=True).stdout


def load_old(commit: str, tmp: Path) -> Any:
    """The RELS kernel module of ``commit``, imported as a package of its own."""
    package = f"rels_{commit}"
    folder = tmp / package
    folder.mkdir()
    (folder / "__init__.py").write_text("")
    files = ["_kernels.py"] + (["_simd.py"] if commit == IR_KERNEL else [])
    for name in files:
        text = git_show(commit, f"src/ehss/identification/{name}")
        text = text.replace("from ehss.identification._simd", f"from {package}._simd")
        (folder / name).write_text(text)
    sys.path.insert(0, str(tmp))
    return importlib.import_module(f"{package}._kernels")


#: a kernel run over (u, y): seconds
Run = Callable[[np.ndarray, np.ndarray], float]


def p0(na: int, nb: int, nc: int, alpha: float = 1e6) -> Any:
    return np.diag(np.full(na + nb + 1 + nc, alpha))


def runner_this(entry: Any, na: int, nb: int, nc: int, lam: float, method: str) -> Run:
    """A run of this tree's loop ``entry`` over (u, y) from θ̂ = 0, P(0) = 1e6 I."""
    n = na + nb + 1 + nc

    def run(u: np.ndarray, y: np.ndarray) -> float:
        s = RelsSettings(na=na, nb=nb, nc=nc, forgetting=lam, method=method).kernel()
        block, _ = new_state(s, np.zeros(n))
        rec = K.record(u, y)
        t0 = time.thread_time()
        entry(block, rec, np.empty((0, n)), 1, True)
        return time.thread_time() - t0

    return run


def runner_3b7(mod: Any, na: int, nb: int, nc: int, lam: float, method: str) -> Run:
    n = na + nb + 1 + nc

    def run(u: np.ndarray, y: np.ndarray) -> float:
        s = mod.RelsSettings(na, nb, nc, 1, lam, 1e6, 1e6, n * 1e6, 0.99,
                             method == "rml" and nc > 0, True)
        block = mod.new_block(s)
        mod.state_views(block).P[:] = p0(na, nb, nc)
        rec = mod.record(u, y)
        t0 = time.thread_time()
        mod.rels_run(block, rec, np.empty((0, n)), 1, True)
        return time.thread_time() - t0

    return run


def runner_b935(mod: Any, na: int, nb: int, nc: int, lam: float, method: str) -> Run:
    n = na + nb + 1 + nc

    def run(u: np.ndarray, y: np.ndarray) -> float:
        st = mod.new_state_buffer(na, nb, nc, 1)
        for index, value in ((mod.H_NA, na), (mod.H_NB, nb), (mod.H_NC, nc),
                             (mod.H_DELAY, 1), (mod.H_LAM, lam), (mod.H_ALPHA, 1e6),
                             (mod.H_ALPHA_C, 1e6), (mod.H_TRMAX, n * 1e6),
                             (mod.H_CRADIUS, 0.99), (mod.H_ENABLED, 1.0),
                             (mod.H_METHOD, mod.METHOD_RML if method == "rml"
                              else mod.METHOD_RELS)):
            st[index] = value
        mod.state_views(st)[1][:] = p0(na, nb, nc)
        err, xi = np.empty(u.size), np.empty(u.size)
        t0 = time.thread_time()
        mod.rels_run(st, u, y, err, xi, np.empty((0, n)), 1)
        return time.thread_time() - t0

    return run


def best_rate(run: Run, u: np.ndarray, y: np.ndarray, repeats: int) -> float:
    run(u[:50], y[:50])  # compile or load from the cache
    return u.size / min(run(u, y) for _ in range(repeats))


# ---------------------------------------------------------------- measurements
def single_channel(old: dict, n_samples: int, repeats: int, rounds: int) -> None:
    na, nb, nc = 6, 6, 4
    u, y = record_of(n_samples)
    spec = K.kernel_for(na, nb, nc, 1, compile_now=True)
    generic = K.rels_run.compile(K.RELS_RUN_SIGNATURE)
    names = ["specialised", "generic", *old]
    print(f"\n### one channel, (6,6,4), n = 17, {n_samples} samples: ns a sample "
          f"(best of {repeats}) and ratios, round by round\n")
    print(f"| variant | {' | '.join(names)} | specialised / {BASELINE} | "
          f"specialised / {IR_KERNEL} | generic / {BASELINE} |")
    print("|---" * (len(names) + 4) + "|")
    for method, lam in VARIANTS:
        runs = {"specialised": runner_this(spec, na, nb, nc, lam, method),
                "generic": runner_this(generic, na, nb, nc, lam, method)}
        for name, (mod, make) in old.items():
            runs[name] = make(mod, na, nb, nc, lam, method)
        rates: dict[str, list[float]] = {name: [] for name in runs}
        for _ in range(rounds):
            for name, run in runs.items():
                rates[name].append(best_rate(run, u, y, repeats))
        best = {name: max(r) for name, r in rates.items()}
        print(f"| {method.upper()} λ = {lam:g} | "
              + " | ".join(f"{1e9 / best[name]:.0f}" for name in names)
              + f" | {ratio(rates, 'specialised', BASELINE)}"
              f" | {ratio(rates, 'specialised', IR_KERNEL)}"
              f" | {ratio(rates, 'generic', BASELINE)} |")


def ratio(rates: dict, a: str, b: str) -> str:
    """Median of the round-by-round speed ratios a / b, and the rounds."""
    if b not in rates:
        return "–"
    each = [x / z for x, z in zip(rates[a], rates[b], strict=True)]
    return f"**{np.median(each):.2f}** ({', '.join(f'{r:.2f}' for r in each)})"


def _bank_run(na: int, nb: int, nc: int, n_ch: int) -> Run:
    """A run of the bank kernel over (u, y), each (N, n_ch), from θ̂ = 0, P(0) = 1e6 I."""
    n = na + nb + 1 + nc
    s = RelsSettings(na=na, nb=nb, nc=nc).kernel()  # P(0) = 1e6 I, tr P <= n·1e6
    bank = B.bank_kernel(na, nb, nc, 1)

    def run_bank(uu: np.ndarray, yy: np.ndarray) -> float:
        blocks = B.new_blocks(s, n_ch)
        for c in range(n_ch):
            start_state(blocks[c], s, np.zeros(n))
        rec = B.bank_record(uu, yy)
        t0 = time.thread_time()
        bank(blocks, rec, True)
        return time.thread_time() - t0

    return run_bank


def _eight_runs(run: Run, u: np.ndarray, y: np.ndarray) -> Run:
    """One single-channel ``run`` per column of (u, y), in turn (their seconds)."""
    columns = [(np.ascontiguousarray(u[:, c]), np.ascontiguousarray(y[:, c]))
               for c in range(u.shape[1])]
    run(*(x[:50] for x in columns[0]))  # compile or load from the cache

    def total(uu: np.ndarray, yy: np.ndarray) -> float:  # uu, yy unused: the
        # channels' own columns
        return sum(run(*column) for column in columns)

    return total


def many_channels(old: dict, n_samples: int, repeats: int, rounds: int) -> None:
    na, nb, nc, n_ch = 4, 3, 4, 8
    u, y = record_of(n_samples, n_ch, seed=7)
    run_bank = _bank_run(na, nb, nc, n_ch)
    singles = {"specialised": runner_this(K.kernel_for(na, nb, nc, 1, compile_now=True),
                                          na, nb, nc, 1.0, "rels"),
               "generic": runner_this(K.rels_run.compile(K.RELS_RUN_SIGNATURE),
                                      na, nb, nc, 1.0, "rels")}
    if BASELINE in old:
        mod, _ = old[BASELINE]
        singles[BASELINE] = runner_3b7(mod, na, nb, nc, 1.0, "rels")

    ns: dict[str, list[float]] = {"bank": [], **{k: [] for k in singles}}
    for _ in range(rounds):
        ns["bank"].append(1e9 / best_rate(run_bank, u, y, repeats))  # u.size = N·C
        for name, run in singles.items():
            full = _eight_runs(run, u, y)
            ns[name].append(1e9 * min(full(u, y) for _ in range(repeats))
                            / (n_samples * n_ch))
    print(f"\n### eight channels of (4,3,4), n = 12, RELS λ = 1, {n_samples} samples "
          "each: ns a channel-sample (best of rounds) and the bank's ratio\n")
    print("| eight channels as | ns / channel-sample | bank speed-up (round by round) |")
    print("|---|---|---|")
    for name, values in ns.items():
        ratios = [a / b for a, b in zip(values, ns["bank"], strict=True)]
        label = "one bank kernel" if name == "bank" else f"eight {name} runs"
        print(f"| {label} | {min(values):.1f} | **{np.median(ratios):.2f}** "
              f"({', '.join(f'{r:.2f}' for r in ratios)}) |")


# ---------------------------------------------------------------- P pass layouts
def _lanes_pass(n_: int, fastmath: Any) -> Any:
    """(22) on C channels in SIMD lanes, P[(i n + j) L + c] (channel innermost, L a
    run-time count), g = P r in the same pass: ``run(P, w, r, g, L, reps)``."""

    @njit(error_model="numpy", fastmath=fastmath)
    def run(P: np.ndarray, w: np.ndarray, r: np.ndarray, g: np.ndarray, L: int,
            reps: int) -> None:
        for _ in range(reps):
            g[:] = 0.0
            for i in range(n_):
                for j in range(n_):
                    o = (i * n_ + j) * L
                    for c in range(L):  # P_ij ← P_ij − w_i w_j;  g_j += P_ij r_i
                        p = P[o + c] - w[i * L + c] * w[j * L + c]
                        P[o + c] = p
                        g[j * L + c] += p * r[i * L + c]

    return run


def _flat_pass(n_: int, fastmath: Any) -> Any:
    """As :func:`_lanes_pass`, each row's (j, c) update one loop over j L + c, with
    row i's w_i and r_i tiled once per row into arrays of length n L."""

    @njit(error_model="numpy", fastmath=fastmath)
    def run(P: np.ndarray, w: np.ndarray, r: np.ndarray, g: np.ndarray, L: int,
            reps: int) -> None:
        m = n_ * L
        wt, rt = np.empty(m), np.empty(m)
        for _ in range(reps):
            g[:] = 0.0
            for i in range(n_):
                for j in range(n_):
                    for c in range(L):
                        wt[j * L + c] = w[i * L + c]
                        rt[j * L + c] = r[i * L + c]
                for k in range(m):  # P_ij ← P_ij − w_i w_j;  g_j += P_ij r_i
                    p = P[i * m + k] - wt[k] * w[k]
                    P[i * m + k] = p
                    g[k] += p * rt[k]

    return run


def _row_pass(n_: int, fastmath: Any) -> Any:
    """The bank's P pass: the single-channel pass (four rows at a time) on each
    channel in turn, ``run(P, w, r, g, reps)`` with one channel a row."""

    @njit(error_model="numpy", fastmath=fastmath)
    def run(P: np.ndarray, w: np.ndarray, r: np.ndarray, g: np.ndarray,
            reps: int) -> None:
        for _ in range(reps):
            for c in range(P.shape[0]):
                K._update_P_and_gain(P[c], w[c], 1.0, r[c], g[c], n_)

    return run


def _on_lines(shape: tuple[int, ...], value: float) -> np.ndarray:
    """An array of ``shape`` filled with ``value``, starting on a 64-byte line."""
    a = K.aligned_copy(np.full(int(np.prod(shape)), value))
    return a.reshape(shape)


def _pass_ns(n: int, lanes: int, reps: int, repeats: int) -> dict[str, float]:
    """ns a channel of one P pass, n = 12, in each layout (rows padded to 16)."""
    rng = np.random.default_rng(3)
    out = {}
    for fm, tag in ((False, ""), ({"contract"}, ", contract")):
        row = _row_pass(n, fm)
        args: tuple[Any, ...] = (_on_lines((8, n * n), 1e-3), _on_lines((8, 16), 1e-9),
                                 _on_lines((8, 16), 1.0), _on_lines((8, 16), 0.0))
        out[f"one channel at a time (the bank){tag}"] = _best_ns(row, args, reps, repeats, 8)
        for name, make in (("lanes", _lanes_pass), ("lanes, (j, c) one loop", _flat_pass)):
            kernel = make(n, fm)
            for L in (lanes, 2 * lanes):
                vectors = [_on_lines((n * L,), 0.0) for _ in range(3)]
                vectors[0][:] = 1e-9 * rng.standard_normal(n * L)
                vectors[1][:] = rng.standard_normal(n * L)
                args = (_on_lines((n * n * L,), 1e-3), *vectors, L)
                out[f"{name}, L = {L} (run time){tag}"] = _best_ns(kernel, args, reps,
                                                                    repeats, L)
    return out


def _best_ns(kernel: Any, args: tuple[Any, ...], reps: int, repeats: int, channels: int) -> float:
    kernel(*args, 1)
    best = np.inf
    for _ in range(repeats):
        t0 = time.thread_time()
        kernel(*args, reps)
        best = min(best, time.thread_time() - t0)
    return 1e9 * best / (reps * channels)


def lane_layouts(old: dict, n_samples: int, repeats: int, rounds: int) -> None:
    """The P pass of (4,3,4), n = 12, per channel in each layout, against the whole
    step of the bank and of eight 3b7a2e5 runs (ns a channel-sample): the bound the
    pass alone sets on a lanes kernel's speed-up."""
    na, nb, nc, n_ch = 4, 3, 4, 8
    n = na + nb + 1 + nc
    u, y = record_of(n_samples, n_ch, seed=7)
    whole = {"bank step": _bank_run(na, nb, nc, n_ch)}
    if BASELINE in old:
        whole[f"{BASELINE} step"] = _eight_runs(runner_3b7(old[BASELINE][0], na, nb, nc,
                                                           1.0, "rels"), u, y)
    ns: dict[str, list[float]] = {}
    for _ in range(rounds):
        for name, run in whole.items():
            ns.setdefault(name, []).append(1e9 / best_rate(run, u, y, repeats))
        for name, value in _pass_ns(n, n_ch, 20_000, repeats).items():
            ns.setdefault(name, []).append(value)
    ref = ns.get(f"{BASELINE} step", ns["bank step"])
    peak = 2 * 4 * 2 * 2.6  # GFLOP/s: 2 FMA units × 4 doubles × 2 flops, 2.6 GHz
    print(f"\n### P pass of (4,3,4), n = 12 ({4 * n * n} flops a channel), by layout, "
          f"against the whole step: ns a channel (best of rounds), {BASELINE}'s step "
          "/ it (round by round), share of the 256-bit FMA peak\n")
    print(f"| what | ns / channel | {BASELINE} step / it | of {peak:.1f} GFLOP/s |")
    print("|---|---|---|---|")
    for name, values in ns.items():
        ratios = [a / b for a, b in zip(ref, values, strict=True)]
        flops = 4 * n * n + (10 * n if name.endswith("step") else 0)
        print(f"| {name} | {min(values):.1f} | **{np.median(ratios):.2f}** "
              f"({', '.join(f'{r:.2f}' for r in ratios)}) | "
              f"{flops / min(values) / peak:.0%} |")


def streaming(calls: int) -> None:
    rng = np.random.default_rng(1)
    u, y = rng.standard_normal(calls).tolist(), rng.standard_normal(calls).tolist()
    out = []
    for method in ("rels", "rml"):
        for spec in (False, True):
            if spec:
                R.specialise_rels(na=6, nb=6, nc=4, delay=1)
            est = RelsEstimator(na=6, nb=6, nc=4, delay=1, method=method)
            est.update(0.1, 0.2)
            upd = est.update
            pc = time.perf_counter_ns
            ts = np.empty(calls)
            for k in range(calls):
                t0 = pc()
                upd(u[k], y[k])
                ts[k] = pc() - t0
            out.append(f"{method.upper()} {'specialised' if spec else 'generic'} "
                       f"{np.median(ts):.0f} ns")
    bank = RelsBank(n_channels=8, na=4, nb=3, nc=4, delay=1)
    uu, yy = rng.standard_normal((calls, 8)), rng.standard_normal((calls, 8))
    bank.update(uu[0], yy[0])
    ts = np.empty(calls)
    for k in range(calls):
        t0 = time.perf_counter_ns()
        bank.update(uu[k], yy[k])
        ts[k] = time.perf_counter_ns() - t0
    print(f"\nRelsEstimator.update median, (6,6,4), {calls} calls (perf_counter_ns around "
          f"each): {', '.join(out)}; RelsBank.update, 8 channels of (4,3,4): "
          f"{np.median(ts):.0f} ns a call ({np.median(ts) / 8:.0f} ns a channel)")


COLD = """
import time
t0, c0 = time.perf_counter(), time.process_time()
import numpy as np
from ehss.identification.rels import RelsEstimator, rels
ci = time.process_time()
u = np.random.default_rng(0).standard_normal(200)
rels(u, np.roll(u, 1), na=2, nb=1, nc=2)
rels(u, np.roll(u, 1), na=2, nb=1, nc=2, method="rml")
est = RelsEstimator(na=2, nb=1, nc=2)
est.update(0.1, 0.2)
est.update_many(u, u)
t1, c1 = time.perf_counter(), time.process_time()
from ehss.identification.rels import specialise_rels
specialise_rels(na=6, nb=6, nc=4, delay=1)
t2, c2 = time.perf_counter(), time.process_time()
from ehss.identification.bank import RelsBank
RelsBank(n_channels=8, na=4, nb=3, nc=4).update(np.ones(8), np.ones(8))
t3, c3 = time.perf_counter(), time.process_time()
print(c1 - c0, t1 - t0, c2 - c1, t2 - t1, c3 - c2, t3 - t2, ci - c0)
"""

WARM = """
import time
t0, c0 = time.perf_counter(), time.process_time()
import numpy as np
from ehss.identification.rels import specialise_rels
specialise_rels(na=6, nb=6, nc=4, delay=1)
print(time.process_time() - c0, time.perf_counter() - t0)
"""


def extract(commit: str, into: Path) -> Path:
    """``src/ehss`` of ``commit`` (git archive) under ``into``; returns the src folder."""
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", "--format=tar", commit,
                              "src/ehss"], capture_output=True, check=True).stdout
    into.mkdir(parents=True, exist_ok=True)
    (into / "src.tar").write_bytes(archive)
    with tarfile.open(into / "src.tar") as tar:
        tar.extractall(into, filter="data")
    return into / "src"


def compile_times(tmp: Path, rounds: int = COMPILE_ROUNDS) -> None:
    def python(code: str, src: Path, cache: Path) -> Any:
        env = {**os.environ, "PYTHONPATH": str(src), "NUMBA_CACHE_DIR": str(cache)}
        out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                             text=True, check=True)
        return [float(v) for v in out.stdout.split()]

    base_src = extract(BASELINE, tmp / "baseline-tree")
    base_code = COLD.split("t1, c1")[0] + "print(time.process_time() - c0, " \
        "time.perf_counter() - t0, 0, 0, 0, 0, ci - c0)"
    # alternating rounds, each with empty caches: one cold compile varies by ±10 % on a
    # shared machine, so the medians and each round's ratio are reported
    bases, colds = [], []
    for r in range(rounds):
        bases.append(python(base_code, base_src, tmp / f"cold-base-{r}"))
        colds.append(python(COLD, ROOT / "src", tmp / f"cold-cache-{r}"))
    warm = python(WARM, ROOT / "src", tmp / "cold-cache-0")
    base = np.median(bases, axis=0)
    cold = np.median(colds, axis=0)
    each = ", ".join(f"{c[0] / b[0]:.2f}" for c, b in zip(colds, bases, strict=True))
    print("\nCompile, fresh process, empty numba cache (CPU s / wall s, median of "
          f"{rounds} alternating rounds): identification kernels used by "
          f"`ehss reproduce` (rels + rml, batch + streaming, generic loop) "
          f"{cold[0]:.1f} / {cold[1]:.1f}, of which {cold[6]:.1f} CPU s importing (the tree "
          f"at {BASELINE}: {base[0]:.1f} / {base[1]:.1f}, {base[6]:.1f} importing; CPU "
          f"ratio this / {BASELINE} round by round: {each}); first use "
          f"of new orders, specialise_rels(6,6,4,1) {cold[2]:.1f} / {cold[3]:.1f}; a "
          f"RelsBank's first use of its orders {cold[4]:.1f} / {cold[5]:.1f}; the "
          f"specialised loop loaded from the disk cache by a later process (import "
          f"included) {warm[0]:.2f} / {warm[1]:.2f}")


def machine() -> str:
    model = platform.processor() or "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return (f"nproc={os.cpu_count()}, CPU {model}, Python {platform.python_version()}, "
            f"numpy {np.__version__}, numba {numba.__version__}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--quick", action="store_true", help="fewer samples (smoke run)")
    p.add_argument("--rounds", type=int, default=3, help="alternating rounds")
    p.add_argument("--lanes", action="store_true",
                   help="only the P pass by layout against the whole step")
    p.add_argument("--compile", action="store_true",
                   help="only the cold compile (with --rounds alternating rounds)")
    args = p.parse_args()
    n_big = 10**5 if args.quick else 10**6
    repeats = 3 if args.quick else 5
    print(f"machine: {machine()}; load average {os.getloadavg()[0]:.1f} at the start")
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        os.environ.setdefault("NUMBA_CACHE_DIR", str(tmp / "cache"))
        if args.compile:
            compile_times(tmp, args.rounds)
            print(f"\nload average {os.getloadavg()[0]:.1f} at the end")
            return
        old = {}
        for commit, make in ((BASELINE, runner_3b7), (IR_KERNEL, runner_b935)):
            try:
                old[commit] = (load_old(commit, tmp), make)
            except Exception as exc:  # noqa: BLE001 - reported, the rest still runs
                print(f"kernel of {commit} not loaded: {type(exc).__name__}: {exc}")
        if args.lanes:
            lane_layouts(old, n_big // 5, repeats, args.rounds)
        else:
            single_channel(old, n_big, repeats, args.rounds)
            many_channels(old, n_big // 5, repeats, args.rounds)
            lane_layouts(old, n_big // 5, repeats, args.rounds)
            streaming(10_000 if args.quick else 100_000)
            compile_times(tmp)
    print(f"\nload average {os.getloadavg()[0]:.1f} at the end")


if __name__ == "__main__":
    main()
