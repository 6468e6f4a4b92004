"""``ehss reproduce``: run the paper's experiments on the simulated rig and write a report."""

from __future__ import annotations

import argparse
import sys
import time

from ehss.cli import add_command
from ehss.cli._outputs import InputFile, OutputFolder
from ehss.cli._simulate import whole_number

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    p = add_command(
        sub, "reproduce",
        description="Step tests of the three loops, then identification of the position, "
        "acceleration and force closed loops with RELS, each validated against the "
        "Hann-window H1 estimate and on held-out data. Writes report.html, report.md, "
        "models.json, summary.json, the figures and the data records into --out.",
    )
    p.add_argument("--out", default=OutputFolder("report"), metavar="DIR", type=OutputFolder,
                   help="output folder (default: report)")
    p.add_argument("--params", metavar="FILE.toml", type=InputFile,
                   help="rig parameters (default preset if omitted)")
    p.add_argument("--seed", type=int, default=0, help="seed of every random signal (default 0)")
    p.add_argument("--duration", type=float, default=40.0, metavar="S",
                   help="seconds of each identification record (default 40)")
    p.add_argument("--jobs", type=_jobs, default=None, metavar="N",
                   help="processes to use, this one included: the compensation "
                   "demonstrations and some figures run in a second one (default 2 where "
                   "the machine has two cores or more; more than 2 gain nothing, so at "
                   "most 2 are used; the report is the same; use 1 when other jobs keep "
                   "the cores busy)")
    p.add_argument("--quiet", action="store_true", help="no progress output")
    p.set_defaults(func=run)


def _jobs(text: str) -> int:
    return whole_number(text, lo=1, what="at least 1")


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from rich.console import Console
    from threadpoolctl import threadpool_limits

    from ehss.cli._dataargs import report_warnings
    from ehss.cli._params import warn_if_unstable
    from ehss.errors import DataError
    from ehss.experiments import ProgrammeSettings, run_programme
    from ehss.experiments.pool import PROGRAMME_STRANDS, default_jobs, process_pool
    from ehss.params import load_params, preset
    from ehss.report import compensation_file, write_report

    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise DataError(f"--out {str(out)!r} is a file, not a folder")
    params = load_params(args.params) if args.params else preset("default")
    for loop in ("position", "acceleration", "force"):
        warn_if_unstable("reproduce", params, loop, f"--params {args.params}")
    settings = ProgrammeSettings(seed=args.seed, duration_s=args.duration)
    console = Console(stderr=True, quiet=args.quiet)
    t0 = time.perf_counter()
    # The programme's linear algebra is on single records and small matrices, where
    # handing work to BLAS threads costs far more than it saves (a norm of 12 000
    # samples: 3 ms with threads on a busy two-core machine, 3 µs without).
    # The workers of the pool keep BLAS to one thread too (ehss.experiments.pool).
    # one process per strand of the programme at most: each costs its imports and memory
    jobs = default_jobs() if args.jobs is None else min(args.jobs, PROGRAMME_STRANDS)
    with (console.status("starting") as status, threadpool_limits(limits=1, user_api="blas"),
          process_pool(jobs) as executor):

        def progress(msg: str) -> None:
            console.log(msg)
            status.update(msg)

        with report_warnings("reproduce"):
            result = run_programme(params, settings, progress=progress, executor=executor)
            status.update("writing the report")
            html_path = write_report(result, out, executor=executor)
    console.log(f"done in {time.perf_counter() - t0:.1f} s")
    lines = []
    for name, r in result.loops.items():
        chk = r.paper
        verdict = "meets acceptance" if chk.passes else "does not meet acceptance"
        lines.append(
            f"{name:>12}: {chk.label}: max |dG| {chk.error.max_magnitude_db:.2f} dB, "
            f"max dphi {chk.error.max_phase_deg:.2f} deg, held-out fit {_pct(chk.fit_pct)} % "
            f"-> {verdict}"
        )
        if r.passing is not None:
            p = r.passing
            lines.append(
                f"{'':>12}  {p.label}: {p.error.max_magnitude_db:.2f} dB, "
                f"{p.error.max_phase_deg:.2f} deg, fit {_pct(p.fit_pct)} % -> meets acceptance"
            )
    for name, demo in result.compensation.items():
        band = demo.compensation_model.band_hz
        where = "no validated band" if band is None else f"band {band[0]:g}-{band[1]:g} Hz"
        gain = demo.without.rms_error["random"] / demo.one_shot_rms_error["random"]
        lines.append(f"{name:>12}: compensate with {out / compensation_file(name)} "
                     f"({where}; one shot {gain:.0f}x less RMS error on the demonstration's "
                     "random reference)")
    print("\n".join(lines))
    print(f"report: {html_path}")
    sys.stdout.flush()
    return 0


def _pct(x: float) -> str:
    """A fit in %: one decimal, or three significant digits for a model that diverges
    (a fit of −3.6e+33 %)."""
    return f"{x:.1f}" if abs(x) < 1e4 else f"{x:.3g}"
