"""``ehss frf``: non-parametric frequency response (H1 and coherence) of a record."""

from __future__ import annotations

import argparse
from pathlib import Path

from ehss.cli._dataargs import add_record_arguments, load_record, write_outputs
from ehss.cli._outputs import OutputFile, OutputTable
from ehss.errors import ParameterError

__all__ = ["register", "run"]


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "frf",
        help="H1 frequency response and coherence of an input/output record (CSV)",
        description="Estimate the frequency response from --input to --output with Welch "
        "averages of Hann-windowed segments (H1 = S_uy / S_uu) and the coherence, and write "
        "columns freq_hz, magnitude_db, phase_deg, coherence.",
    )
    add_record_arguments(p)
    p.add_argument("--nperseg", type=int, metavar="N",
                   help="segment length in samples (default: a power of two near fs, "
                   "about 1 Hz resolution, with at least 8 averages when possible)")
    p.add_argument("--noverlap", type=int, metavar="N",
                   help="segment overlap in samples (default: nperseg/2)")
    p.add_argument("--out", required=True, metavar="FRF.csv", type=OutputTable,
                   help="table to write: .csv (with a .json sidecar), .parquet, .h5, .npz "
                   "or .mat")
    p.add_argument("--plot", metavar="FRF.png", type=OutputFile, help="also write a Bode plot")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ehss._provenance import versions
    from ehss.frequency import h1_estimate
    from ehss.io import table_writers

    if args.nperseg is not None and args.nperseg < 4:
        raise ParameterError(f"--nperseg {args.nperseg} must be >= 4")
    rec = load_record(args)
    frf = h1_estimate(rec.u, rec.y, rec.fs, nperseg=args.nperseg, noverlap=args.noverlap)
    sidecar = {
        "what": f"H1 estimate {args.input} -> {args.output}",
        "data": str(rec.path),
        "fs_hz": rec.fs,
        "window": "hann",
        "nperseg": frf.nperseg,
        "n_averages": frf.n_averages,
        "resolution_hz": frf.resolution_hz,
        "units": {"freq_hz": "Hz", "magnitude_db": "dB", "phase_deg": "deg", "coherence": "-"},
        "versions": versions(),
    }
    good = frf.coherence >= 0.9
    print(f"H1 estimate {args.input} -> {args.output}: {frf.freq_hz.size} frequencies "
          f"{frf.freq_hz[0]:.4g}..{frf.freq_hz[-1]:.4g} Hz, resolution "
          f"{frf.resolution_hz:.4g} Hz, {frf.n_averages} averages of {frf.nperseg} samples; "
          f"coherence >= 0.9 at {int(good.sum())} of them")
    out = Path(args.out)
    writers = table_writers(out, frf.to_columns(), sidecar)
    if args.plot is not None:
        from ehss.plots import DPI, bode_compare

        fig = bode_compare(frf, None, title=f"{rec.path.name}: {args.input} → {args.output}")
        writers[Path(args.plot)] = lambda tmp: fig.savefig(tmp, dpi=DPI, format="png",
                                                           bbox_inches="tight")
    write_outputs(writers)
    return 0
