"""Closed-loop simulation speed: real-time factor of the nonlinear simulator.

For each loop, the nonlinear closed-loop simulation (plant integrated with RK4 at the
internal rate, controller at the control rate) is timed as a real-time factor (simulated
seconds per wall second). Numba compile time is measured separately: the kernels are
compiled into a fresh, empty cache directory (first call of each loop, in a fresh process)
and then timed on later calls.
In the same run, python-control's ``forced_response`` simulates the linearised position
closed loop (eq (9), ``ehss.linear.position_closed_loop``) over the same time grid.

With ``--against OTHER_SRC`` (e.g. another checkout's ``src``, unpacked with
``git archive main src | tar -x -C /tmp/base``) the script instead compares the ehss on
its own ``PYTHONPATH`` ("this") with the one in OTHER_SRC ("other") in one run, fairly on a
shared machine: cold compiles alternate between fresh processes with empty caches (CPU
time of the first call), and warm runs alternate, one at a time, between two worker
processes, so that both sides see the same load; minima, medians and the median of the
paired ratios are reported.

Usage::

    python benchmarks/bench_simulation.py [--duration 20] [--repeat 5] [--markdown out.md]
    PYTHONPATH=src python benchmarks/bench_simulation.py --against /tmp/base/src \
        [--rounds 40] [--cold 5]
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import tempfile
import time

# compile into an empty cache so that the first call measures the real JIT time
os.environ.setdefault("NUMBA_CACHE_DIR", tempfile.mkdtemp(prefix="ehss-bench-numba-"))

import numpy as np  # noqa: E402

GRAVITY_M_S2 = 9.80665


def _cpu_model() -> str:
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def _references(n: int, fs: float) -> dict[str, np.ndarray]:
    """A smooth, feasible band-limited test per loop (random phases, fixed seed)."""
    t = np.arange(n) / fs
    rng = np.random.default_rng(0)
    freqs = np.array([0.7, 1.9, 3.1, 5.3, 8.9])
    ph = rng.uniform(0, 2 * np.pi, freqs.size)
    shape = np.sin(2 * np.pi * freqs[:, None] * t + ph[:, None]).sum(axis=0) / freqs.size
    return {
        "position": 2e-3 * shape,
        "acceleration": 0.1 * GRAVITY_M_S2 * shape,
        "force": 245.0 + 500.0 * shape,
    }


def _best_of(fn, repeat: int) -> float:
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


LOOPS = ("position", "acceleration", "force")


def _worker(duration: float) -> int:
    """Serve timed runs: one loop name per stdin line, its wall time on stdout."""
    from ehss.params import preset
    from ehss.simulation import simulate

    params = preset("default")
    fs = params.timing.control_rate_hz
    refs = _references(int(round(duration * fs)), fs)
    for loop in LOOPS:
        simulate(loop, refs[loop], params=params, seed=1)
    print("ready", flush=True)
    for line in sys.stdin:
        loop = line.strip()
        t0 = time.perf_counter()
        simulate(loop, refs[loop], params=params, seed=1)
        print(f"{time.perf_counter() - t0:.6f}", flush=True)
    return 0


def _cold_first_call() -> int:
    """Print the CPU and wall time of the first simulate call (compile, empty cache)."""
    from ehss.params import preset
    from ehss.simulation import simulate

    c0, w0 = time.process_time(), time.perf_counter()
    simulate("position", np.zeros(10), params=preset("default"), seed=0)
    print(f"{time.process_time() - c0:.3f} {time.perf_counter() - w0:.3f}")
    return 0


def _compare(other_src: str, duration: float, rounds: int, cold: int) -> int:
    """This ehss against the one in ``other_src``, interleaved (see the module docstring)."""
    this_src = os.environ.get("PYTHONPATH", "")
    sides = {"this": this_src, "other": other_src}
    script = os.path.abspath(__file__)

    def env(src: str, cache: str) -> dict[str, str]:
        return dict(os.environ, PYTHONPATH=src, NUMBA_CACHE_DIR=cache)

    cold_cpu: dict[str, list[float]] = {s: [] for s in sides}
    for _ in range(cold):
        for side, src in sides.items():
            out = subprocess.run([sys.executable, script, "--cold-first-call"], check=True,
                                 capture_output=True, text=True,
                                 env=env(src, tempfile.mkdtemp(prefix="ehss-bench-cold-")))
            cold_cpu[side].append(float(out.stdout.split()[0]))
    workers = {}
    for side, src in sides.items():
        workers[side] = subprocess.Popen(
            [sys.executable, script, "--worker", "--duration", str(duration)],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
            env=env(src, tempfile.mkdtemp(prefix="ehss-bench-warm-")))
        assert workers[side].stdout.readline().strip() == "ready"
    wall = {(s, loop): [] for s in sides for loop in LOOPS}
    for r in range(rounds):
        for loop in LOOPS:
            for side in (("this", "other") if r % 2 == 0 else ("other", "this")):
                w = workers[side]
                w.stdin.write(loop + "\n")
                w.stdin.flush()
                wall[(side, loop)].append(float(w.stdout.readline()))
    for w in workers.values():
        w.stdin.close()
        w.wait()
    print(f"this: PYTHONPATH={this_src}; other: {other_src}; {duration:g} s simulated, "
          f"{rounds} interleaved rounds; cold compile: {cold} fresh processes each")
    print("| run | this: min / median | other: min / median | median this/other |")
    print("|---|---:|---:|---:|")
    for loop in LOOPS:
        a, b = np.array(wall[("this", loop)]), np.array(wall[("other", loop)])
        print(f"| ehss.simulate ({loop}), wall s | {a.min():.4f} / {np.median(a):.4f} | "
              f"{b.min():.4f} / {np.median(b):.4f} | {np.median(a / b):.3f} |")
    a, b = np.array(cold_cpu["this"]), np.array(cold_cpu["other"])
    print(f"| first call, empty cache, CPU s | {a.min():.2f} / {np.median(a):.2f} | "
          f"{b.min():.2f} / {np.median(b):.2f} | {np.median(a / b):.3f} |")
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=20.0, help="simulated seconds per run")
    ap.add_argument("--repeat", type=int, default=5, help="timed runs (best is kept)")
    ap.add_argument("--markdown", metavar="FILE", help="also write the table as markdown")
    ap.add_argument("--against", metavar="OTHER_SRC",
                    help="compare with the ehss in OTHER_SRC, interleaved")
    ap.add_argument("--rounds", type=int, default=40, help="--against: warm rounds")
    ap.add_argument("--cold", type=int, default=5, help="--against: cold compiles per side")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--cold-first-call", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        return _worker(args.duration)
    if args.cold_first_call:
        return _cold_first_call()
    if args.against:
        return _compare(args.against, args.duration, args.rounds, args.cold)

    import control
    import numba

    from ehss.params import preset
    from ehss.simulation import simulate

    params = preset("default")
    fs = params.timing.control_rate_hz
    n = int(round(args.duration * fs))
    refs = _references(n, fs)

    rows = []
    # ---------------------------------------------------------------- JIT compile
    # in a fresh process: the first call compiles the loop kernel (one for every loop);
    # the first acceleration and force calls then add what only they need
    first_call_s = {}
    for loop in ("position", "acceleration", "force"):
        t0 = time.perf_counter()
        simulate(loop, refs[loop][:10], params=params, seed=0)
        first_call_s[loop] = time.perf_counter() - t0
    later_call_s = _best_of(lambda: simulate("position", refs["position"][:10], params=params,
                                             seed=0), 5)

    # ---------------------------------------------------------------- nonlinear loops
    for loop in ("position", "acceleration", "force"):
        ref = refs[loop]
        wall = _best_of(lambda ref=ref, loop=loop: simulate(loop, ref, params=params, seed=1),
                        args.repeat)
        rows.append((f"ehss.simulate ({loop}, nonlinear)", wall, args.duration / wall))

    # ---------------------------------------------------------------- python-control peer
    try:
        from ehss.linear import position_closed_loop

        sys_lin = position_closed_loop(params)
        peer_name = "control.forced_response (eq (9), ehss.linear)"
    except ImportError:  # pragma: no cover - before ehss.linear exists
        wh, zh = params.hydraulic_omega_rad_s, params.hydraulic_damping
        wv, zv = params.valve.omega_rad_s, params.valve.damping
        k = params.position.kp_v_per_m * params.valve.gain_per_v * params.velocity_gain_m_s
        s = control.tf("s")
        ol = k / (s * (s**2 / wv**2 + 2 * zv * s / wv + 1) * (s**2 / wh**2 + 2 * zh * s / wh + 1))
        sys_lin = control.feedback(ol, 1)
        peer_name = "control.forced_response (eq (9), built here)"
    t = np.arange(n) / fs
    u = refs["position"]
    wall_peer = _best_of(lambda: control.forced_response(sys_lin, T=t, U=u), args.repeat)
    rows.append((peer_name, wall_peer, args.duration / wall_peer))
    pos_wall = rows[0][1]

    # ---------------------------------------------------------------- report
    machine = (
        f"{os.cpu_count()} cores, {_cpu_model()}; Python {platform.python_version()}, "
        f"numpy {np.__version__}, numba {numba.__version__}, control {control.__version__}"
    )
    timing = params.timing
    head = (
        f"{args.duration:g} s simulated at {timing.control_rate_hz:g} Hz control / "
        f"{timing.internal_rate_hz:g} Hz internal (RK4), best of {args.repeat}"
    )
    lines = [
        "| run | wall time (s) | real-time factor |",
        "|---|---:|---:|",
        *[f"| {name} | {wall:.4f} | {rtf:,.0f}× |" for name, wall, rtf in rows],
    ]
    extra = [
        f"- JIT: first call (compile into an empty cache, fresh process) "
        f"{first_call_s['position']:.2f} s (position), then "
        f"{first_call_s['acceleration']:.2f} s (acceleration), "
        f"{first_call_s['force']:.2f} s (force, static-force start); later calls "
        f"{later_call_s * 1e3:.2f} ms (10-sample position run).",
        f"- ehss position loop vs forced_response: {wall_peer / pos_wall:.1f}× faster "
        "(nonlinear, with sensors, quantisation and delay vs the linear eq (9)).",
        f"- Machine: {machine}.",
        f"- Command: `python benchmarks/bench_simulation.py --duration {args.duration:g} "
        f"--repeat {args.repeat}`",
    ]
    text = "\n".join([head, "", *lines, "", *extra])
    print(text)
    if args.markdown:
        with open(args.markdown, "w", encoding="utf-8") as fh:
            fh.write(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
