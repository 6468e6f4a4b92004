"""``ehss identify``: identify an ARMAX model of a loop with RELS and validate it."""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

import numpy as np

from ehss.cli._dataargs import (
    add_record_arguments,
    holdout_fraction,
    load_record,
    report_warnings,
    write_outputs,
)
from ehss.cli._outputs import OutputFile
from ehss.errors import ParameterError

__all__ = ["register", "run", "time_plot_path"]


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "identify",
        help="identify an ARMAX model from an input/output record (RELS) and validate it",
        description="Identify A y = q^-d B u + C e with recursive extended least squares "
        "(eqs 19-22) on the first part of the record, validate it on the held-out end "
        "(simulation and prediction fit, H1 frequency-response error, residual tests), print "
        "it at full precision with its poles and zeros, and save it as JSON. The means of "
        "the estimation part are removed first (RELS has no constant term) and stored in "
        "the JSON.",
    )
    add_record_arguments(p)
    p.add_argument("--na", type=int, required=True, metavar="N", help="order of A (>= 1)")
    p.add_argument("--nb", type=int, required=True, metavar="N",
                   help="order of B (b0..b_nb, >= 0)")
    p.add_argument("--nc", type=int, required=True, metavar="N", help="order of C (>= 0)")
    p.add_argument("--delay", type=int, default=1, metavar="D",
                   help="input delay in samples (default: %(default)s)")
    p.add_argument("--method", choices=("rels", "rml"), default="rels",
                   help="rels: the paper's recursive extended least squares (eqs 19-22); "
                   "rml: recursive maximum likelihood, for records whose disturbance is "
                   "mostly sensor noise at the output (use nc = na) (default: %(default)s)")
    p.add_argument("--forgetting", type=float, default=1.0, metavar="LAMBDA",
                   help="forgetting factor λ in (0, 1] (default: %(default)s)")
    p.add_argument("--p0", type=float, default=1e6, metavar="ALPHA",
                   help="initial covariance P(0) = α I (default: %(default)g)")
    p.add_argument("--holdout", type=float, default=0.3, metavar="FRACTION",
                   help="fraction at the end of the record kept for validation "
                   "(default: %(default)s)")
    p.add_argument("--band", nargs=2, type=float, metavar=("LO", "HI"),
                   help="frequency band (Hz) of the frequency-response check "
                   "(default: up to 0.45 fs)")
    p.add_argument("--min-coherence", type=float, default=0.9, metavar="G2",
                   help="H1 points with a lower coherence are not compared "
                   "(default: %(default)s)")
    p.add_argument("--out", required=True, metavar="MODEL.json", type=OutputFile,
                   help="model file to write")
    p.add_argument("--plot", metavar="BODE.png", type=OutputFile,
                   help="write the Bode comparison there, and the time comparison beside it "
                   "(BODE_time.png)")
    p.set_defaults(func=run, derived_outputs=lambda a: [time_plot_path(a.plot)] if a.plot
                   else [])


def time_plot_path(plot: str | Path) -> Path:
    """Where the time comparison goes for ``--plot plot``: ``<stem>_time<suffix>``."""
    plot = Path(plot)
    return plot.with_name(f"{plot.stem}_time{plot.suffix or '.png'}")


def _check_args(args: argparse.Namespace) -> tuple[float, tuple[float, float] | None]:
    holdout = holdout_fraction(args.holdout)
    if holdout == 0.0:
        raise ParameterError("--holdout must be > 0: identify validates on held-out data")
    band = None
    if args.band is not None:
        lo, hi = args.band
        if not (math.isfinite(lo) and math.isfinite(hi) and 0 <= lo < hi):
            raise ParameterError(f"--band {lo:g} {hi:g} must satisfy 0 <= LO < HI")
        band = (lo, hi)
    if not 0.0 <= args.min_coherence <= 1.0:
        raise ParameterError(f"--min-coherence {args.min_coherence} must be in [0, 1]")
    return holdout, band


def run(args: argparse.Namespace) -> int:
    from ehss.identification.rels import rels
    from ehss.validation import validate

    holdout, band = _check_args(args)
    plots = (args.plot, None if args.plot is None else time_plot_path(args.plot))
    rec = load_record(args)
    fs = rec.fs
    n = rec.u.size
    n_est = int(round(n * (1.0 - holdout)))
    # Deviations from the operating point: RELS has no constant term.
    u_mean = float(np.mean(rec.u[:n_est]))
    y_mean = float(np.mean(rec.y[:n_est]))
    u = rec.u - u_mean
    y = rec.y - y_mean
    if band is not None and band[1] > fs / 2:
        raise ParameterError(f"--band upper edge {band[1]:g} Hz is above fs/2 = {fs / 2:g} Hz")
    band_hz = band if band is not None else (0.0, 0.45 * fs)
    with report_warnings("identify"):
        model = rels(
            u[:n_est], y[:n_est], na=args.na, nb=args.nb, nc=args.nc, delay=args.delay,
            forgetting=args.forgetting, p0=args.p0, dt=1.0 / fs, method=args.method,
        )
        report = validate(model, u, y, fs=fs, band_hz=band_hz, holdout=holdout,
                          min_coherence=args.min_coherence)

    import dataclasses

    model = dataclasses.replace(model, offsets=(u_mean, y_mean))
    _print_model(model, report, rec, args)
    doc = model.to_dict()
    doc["validation"] = report.summary()
    doc["provenance"] = _provenance(rec, args, holdout, n_est)

    writers: dict[Path, Any] = {}
    from ehss.io.writers import to_jsonable

    def write_model(tmp: Path) -> None:
        import json

        tmp.write_text(json.dumps(to_jsonable(doc), indent=2, allow_nan=False) + "\n",
                       encoding="utf-8")

    writers[Path(args.out)] = write_model
    if args.plot is not None:
        from ehss.plots import DPI, bode_compare, time_compare

        title = (f"{rec.path.name}: {args.input} → {args.output}, ARMAX "
                 f"({model.na},{model.nb},{model.nc}) d={model.delay}")
        bode = bode_compare(report.frf, {"identified model": model}, band_hz=band_hz,
                            min_coherence=args.min_coherence, title=title)
        window = min(1.0, report.n_validation / fs)
        tfig = time_compare(rec.t, rec.y, {"model (simulated)": report.simulated + y_mean},
                            window_s=window, ylabel=args.output,
                            title=f"held-out data, simulation fit "
                                  f"{report.simulation_fit_pct:.2f} %")

        def saver(fig):
            return lambda tmp: fig.savefig(tmp, dpi=DPI, format="png", bbox_inches="tight")

        writers[Path(plots[0])] = saver(bode)
        writers[Path(plots[1])] = saver(tfig)
    write_outputs(writers)
    return 0


def _provenance(rec, args, holdout: float, n_est: int) -> dict[str, Any]:
    from ehss._provenance import versions

    return {
        "command": "ehss identify",
        "input_file": str(rec.path),
        "columns": {"input": args.input, "output": args.output,
                    "time": args.time_column if args.fs is None else None},
        "fs_hz": rec.fs,
        "n_samples": int(rec.u.size),
        "n_estimation": n_est,
        "settings": {
            "na": args.na, "nb": args.nb, "nc": args.nc, "delay": args.delay,
            "method": args.method, "forgetting": args.forgetting, "p0": args.p0,
            "holdout": holdout,
            "band_hz": None if args.band is None else list(args.band),
            "min_coherence": args.min_coherence,
        },
        "versions": versions(),
    }


def _print_model(model, report, rec, args) -> None:
    from rich.console import Console
    from rich.table import Table

    console = Console(width=120, highlight=False)
    console.print(f"ARMAX ({model.na},{model.nb},{model.nc}), delay {model.delay}, "
                  f"dt = {model.dt!r} s, identified by {args.method.upper()} on "
                  f"{report.n_estimation} samples "
                  f"of {rec.path.name} ({args.input} → {args.output})")
    console.print(model.format_paper(), soft_wrap=True)
    console.print(f"C(q^-1) = {_poly(model.c)}", soft_wrap=True)
    if math.isfinite(model.noise_variance):
        console.print(f"noise variance = {model.noise_variance!r}")
    table = Table(title="poles and zeros of G(z)")
    for col in ("", "z", "|z|", "f (Hz)", "damping"):
        table.add_column(col, justify="right")
    for kind, roots in (("pole", model.poles()), ("zero", model.zeros())):
        for z in sorted(roots, key=lambda r: (-abs(r), np.angle(r))):
            f_hz, zeta = _s_plane(z, model.dt)
            table.add_row(kind, _complex(z), f"{abs(z):.6f}", f_hz, zeta)
    console.print(table)
    dc = model.dc_gain()
    console.print(f"dc gain = {dc!r}; stable: "
                  f"{'yes' if report.stable else 'NO'} "
                  f"(max pole radius {report.max_pole_radius:.6f})")
    console.print(report.format(), soft_wrap=True)


def _poly(c: np.ndarray) -> str:
    terms = [repr(float(c[0]))]
    for i, v in enumerate(c[1:], start=1):
        terms.append(f"{'-' if v < 0 else '+'} {abs(float(v))!r} q^-{i}")
    return " ".join(terms)


def _complex(z: complex) -> str:
    if abs(z.imag) < 1e-14 * max(1.0, abs(z)):
        return f"{z.real:.10g}"
    return f"{z.real:.10g} {'-' if z.imag < 0 else '+'} {abs(z.imag):.10g}j"


def _s_plane(z: complex, dt: float) -> tuple[str, str]:
    """Natural frequency (Hz) and damping of s = ln(z)/dt; '-' for z on the negative axis
    or at the origin, where no continuous-time equivalent exists."""
    if abs(z) == 0 or (abs(z.imag) < 1e-12 and z.real < 0):
        return "-", "-"
    s = np.log(complex(z)) / dt
    wn = abs(s)
    if wn == 0:
        return "0", "-"
    return f"{wn / (2 * np.pi):.4g}", f"{-s.real / wn:.4g}"
