"""Drive-file compensation: model-based (stable inversion, ZPETC) against FRF iteration.

On the same plant and reference, in one run, three ways of building a drive file:

* **stable** — the default: exact stable inversion of the identified model inside its
  validated band, then model-based learning updates (default gain, refused when the error
  grows);
* **zpetc** — the same with ZPETC as the inverse (one-shot and updates);
* **frf** — the industry's non-parametric iteration: the first run plays the reference
  itself, each update inverts the H1 estimate of the last run (weighted by coherence).

Plants: two oversampled servo loops at 4096 Hz (a second order with a real pole, ZOH:
a sampling zero at -3.6; the second with a slow lag pair near z = 1, whose identified
zeros land just outside the unit circle), 0.1 % sensor noise, identified from a noisy
0–100 Hz record by the default workflow (:func:`ehss.workflow.identify`, orders
(4, 3, 4, 1): decimated, ARMAX, validated band from the held-out data), the drive played
at 4096 Hz; and
the simulated rig's position loop (identified by RML (4, 3, 2, 1) on a 0–100 Hz test, band 0–20 Hz).
Reported per run: the normalised RMS error ``100 std(y - r)/std(r)``, the drive's RMS
gain, the J1 lag (samples) and the wall time of each update.

Usage::

    python benchmarks/bench_compensation.py [--iterations 3] [--markdown out.md]
"""

from __future__ import annotations

import argparse
import dataclasses
import platform
import sys
import time

import numpy as np
import scipy.signal


def _oversampled_plant(title, wn_hz, zeta, pole_hz, lag=None):
    """ZOH loop at 4096 Hz: second order x a real pole (x a lag (tz s + 1)/(tp s + 1)),
    identified by the default workflow at (4, 3, 4, 1) from a noisy 0-100 Hz record."""
    from ehss.signals import band_limited_random
    from ehss.workflow import identify

    fs, wn, pole = 4096.0, 2 * np.pi * wn_hz, 2 * np.pi * pole_hz
    num, den = [wn**2 * pole], np.polymul([1, 2 * zeta * wn, wn**2], [1, pole])
    if lag is not None:
        num, den = np.polymul(num, [lag[0], 1]), np.polymul(den, [lag[1], 1])
    b, a, _ = scipy.signal.cont2discrete((num, den), 1 / fs, method="zoh")
    b = np.ravel(b)
    seeds = iter(range(1000, 2000))

    def run(u):
        noise = 2e-6 * np.random.default_rng(next(seeds)).standard_normal(u.size)
        return scipy.signal.lfilter(b, a, u) + noise

    u_id = np.asarray(band_limited_random(band_hz=(0.0, 100.0), duration_s=30.0, fs=fs,
                                          seed=3, rms=2e-3).values)
    y_id = run(u_id)
    # the default workflow: decimated, ARMAX, validated on held-out data (band_hz)
    model = identify(u_id, y_id, fs=fs, orders=(4, 3, 4, 1)).model
    r = np.asarray(band_limited_random(band_hz=(0.2, 20.0), duration_s=16.0, fs=fs, seed=5,
                                       rms=2e-3).values)
    return title, run, model, r, fs


def _rig_plant():
    from ehss.experiments.compensation_demo import LOOP_SETTINGS, random_reference
    from ehss.identification import estimate
    from ehss.params import preset
    from ehss.simulation import simulate

    params = preset("default")
    fs = float(params.timing.control_rate_hz)
    cfg = LOOP_SETTINGS["position"]
    u_id = random_reference(16.0, fs, cfg["ident_hz"], cfg["ident_rms"], seed=0)
    y_id = simulate("position", u_id, params=params, seed=100).output
    o = cfg["orders"]
    model = estimate(u_id, y_id, method="rml", na=o["na"], nb=o["nb"], nc=o["nc"],
                     delay=o["delay"], dt=1 / fs)
    model = dataclasses.replace(model, band_hz=cfg["band_hz"])
    seeds = iter(range(200, 300))

    def run(u):
        return simulate("position", u, params=params, seed=next(seeds)).output

    r = random_reference(16.0, fs, (0.5, 20.0), cfg["test_rms"], seed=1)
    return "simulated rig, position loop (RML 4,3,2,1)", run, model, r, fs


def _iterate(kind: str, run, model, r, fs, iterations: int) -> list[dict]:
    from ehss.compensation import UpdateOptions, compensate, run_record, update_drive

    t0 = time.perf_counter()
    if kind == "frf":
        drive = r.copy()
    else:
        drive = compensate(model, r, fs=fs, method=kind, max_gain=None)
    elapsed = time.perf_counter() - t0
    rows, state = [], None
    inverse = None
    if kind != "frf":
        from ehss.compensation import design_inverse

        inverse = design_inverse(model, method=kind)
    for k in range(iterations + 1):
        y = run(drive)
        if k == iterations:
            rec = run_record(r, drive, y)
            rows.append({"run": k, "record": rec, "update_s": elapsed, "note": ""})
            break
        t0 = time.perf_counter()
        step = update_drive(r, drive, y, fs=fs, model=model,
                            options=UpdateOptions(method="frf" if kind == "frf" else "model"),
                            inverse=inverse, state=state)
        rows.append({"run": k, "record": step.record, "update_s": elapsed,
                     "note": "" if step.accepted else "refused"})
        elapsed = time.perf_counter() - t0
        if step.stopped:
            break
        state, drive = step.state, step.drive
    return rows


def main(argv: list[str] | None = None) -> int:
    import ehss

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--iterations", type=int, default=3)
    p.add_argument("--markdown", metavar="FILE", help="also write the tables to FILE")
    args = p.parse_args(argv)

    lines: list[str] = []
    plants = (
        lambda: _oversampled_plant("oversampled loop, 4096 Hz: 15 Hz, ζ 0.6, 60 Hz pole",
                                   15.0, 0.6, 60.0),
        lambda: _oversampled_plant("oversampled loop with a low-frequency lag, 4096 Hz: "
                                   "12 Hz, ζ 0.7, 80 Hz pole, (0.020 s + 1)/(0.025 s + 1)",
                                   12.0, 0.7, 80.0, lag=(0.020, 0.025)),
        _rig_plant,
    )
    for plant in plants:
        title, run, model, r, fs = plant()
        zeros = ", ".join(f"{z:.3f}" for z in model.zeros())
        title = (f"{title} (model at {1 / model.dt:g} Hz, identified zeros {zeros}; "
                 f"band {model.band_hz[0]:g}-{model.band_hz[1]:.4g} Hz)")
        table = {kind: _iterate(kind, run, model, r, fs, args.iterations)
                 for kind in ("stable", "zpetc", "frf")}
        lines += [f"### {title}", "",
                  "NRMSE % (drive RMS gain, lag in samples) per run; run 0 is the one-shot "
                  "drive (FRF: the reference itself).", "",
                  "| run | stable inversion | ZPETC | FRF iteration |", "|---:|---|---|---|"]
        for k in range(args.iterations + 1):
            cells = []
            for kind in ("stable", "zpetc", "frf"):
                rows = table[kind]
                if k < len(rows):
                    rec = rows[k]["record"]
                    note = f" {rows[k]['note']}" if rows[k]["note"] else ""
                    cells.append(f"{rec.nrmse_percent:.3g} ({rec.drive_rms_gain:.2f}, "
                                 f"{rec.lag_samples:+.2f}){note}")
                else:
                    cells.append("stopped")
            lines.append(f"| {k} | " + " | ".join(cells) + " |")
        unbanded = []
        for kind in ("stable", "zpetc"):
            from ehss.compensation import apply_inverse, design_inverse_tf, run_record

            inv = design_inverse_tf(model.b, model.a, delay=model.delay, dt=model.dt,
                                    method=kind)
            drive = apply_inverse(inv, r, fs)  # at the model's rate, resampled
            rec = run_record(r, drive, run(drive))
            unbanded.append(f"{kind} {rec.nrmse_percent:.3g} % (drive gain "
                            f"{rec.drive_rms_gain:.3g})")
        lines += ["", "Without the band limit (one-shot): " + ", ".join(unbanded) + "."]
        times = {kind: np.median([row["update_s"] for row in rows[1:]]) * 1e3
                 for kind, rows in table.items()}
        lines += ["", "Median wall time per update (ms): " + ", ".join(
            f"{kind} {t:.0f}" for kind, t in times.items()) + f" ({r.size} samples).", ""]
    lines += [f"- Machine: {platform.machine()}, Python {sys.version.split()[0]}, "
              f"numpy {np.__version__}, scipy {scipy.__version__}, ehss {ehss.__version__}.",
              "- Command: `python benchmarks/bench_compensation.py --iterations "
              f"{args.iterations}`"]
    text = "\n".join(lines)
    print(text)
    if args.markdown:
        with open(args.markdown, "w", encoding="utf-8") as fh:
            fh.write(text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
