"""``ehss frf``: non-parametric frequency response (H1 and coherence) of a record."""

from __future__ import annotations

import argparse
from pathlib import Path

from ehss._checks import check_band
from ehss.cli import add_command
from ehss.cli._dataargs import add_record_arguments, load_record, write_outputs
from ehss.cli._outputs import OutputFile, OutputTable
from ehss.errors import ParameterError

__all__ = ["register", "run"]


def register(sub: argparse._SubParsersAction) -> None:
    p = add_command(
        sub, "frf",
        description="Estimate the frequency response from --input to --output and its "
        "coherence, and write columns freq_hz, magnitude_db, phase_deg, coherence. Welch "
        "averages of Hann-windowed segments (H1 = S_uy / S_uu) for random and multisine "
        "tests; for sweeps, the whole record's DFTs averaged over adjacent bins, as a sweep "
        "analyser measures each frequency while the sweep passes it. The segment length "
        "follows the record: at least 8 averages, and no finer resolution than --band needs "
        "(min(LO/2, (HI-LO)/32)).",
    )
    add_record_arguments(p)
    p.add_argument("--nperseg", type=int, metavar="N",
                   help="segment length in samples (default: from the record's length and "
                   "--band, see above)")
    p.add_argument("--noverlap", type=int, metavar="N",
                   help="Welch segment overlap in samples (default: nperseg/2)")
    p.add_argument("--band", nargs=2, type=float, metavar=("LO", "HI"),
                   help="band of interest (Hz), for the default segment length and the "
                   "choice of estimate")
    p.add_argument("--method", choices=("auto", "welch", "dft"), default="auto",
                   help="welch, dft (whole-record DFT, for sweeps) or auto: the one whose "
                   "coherence reaches --min-coherence over more of the band (default: "
                   "%(default)s)")
    p.add_argument("--min-coherence", type=float, default=0.9, metavar="G2",
                   help="coherence counted as good in the summary and by --method auto "
                   "(default: %(default)s)")
    p.add_argument("--out", required=True, metavar="FRF.csv", type=OutputTable,
                   help="table to write: .csv (with a .json sidecar), .parquet, .h5, .npz "
                   "or .mat")
    p.add_argument("--plot", metavar="FRF.png", type=OutputFile, help="also write a Bode plot")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ehss._provenance import versions
    from ehss.frequency import frf_estimate, h1_estimate
    from ehss.io import table_writers

    if args.nperseg is not None and args.nperseg < 4:
        raise ParameterError(f"--nperseg {args.nperseg} must be >= 4")
    if not 0.0 <= args.min_coherence <= 1.0:
        raise ParameterError(f"--min-coherence {args.min_coherence} must be in [0, 1]")
    band = None if args.band is None else check_band(args.band, "--band")
    if args.noverlap is not None and args.method != "welch":
        raise ParameterError("--noverlap applies to Welch averaging: add --method welch")
    rec = load_record(args)
    if band is not None:
        check_band(band, "--band", fs=rec.fs)
    if args.method == "welch":
        frf = h1_estimate(rec.u, rec.y, rec.fs, nperseg=args.nperseg, noverlap=args.noverlap,
                          band_hz=band)
    else:
        frf = frf_estimate(rec.u, rec.y, rec.fs, method=args.method, nperseg=args.nperseg,
                           band_hz=band, min_coherence=args.min_coherence)
    how = ("Welch averages of Hann-windowed segments" if frf.method == "welch" else
           "whole-record DFT averaged over adjacent bins")
    sidecar = {
        "what": f"H1 estimate {args.input} -> {args.output}",
        "data": str(rec.path),
        "fs_hz": rec.fs,
        "method": frf.method,
        "estimate": how,
        "window": "hann" if frf.method == "welch" else "tukey(0.1) over the record",
        "nperseg": frf.nperseg,
        "n_averages": frf.n_averages,
        "resolution_hz": frf.resolution_hz,
        "band_hz": None if band is None else list(band),
        "units": {"freq_hz": "Hz", "magnitude_db": "dB", "phase_deg": "deg", "coherence": "-"},
        "versions": versions(),
    }
    g = args.min_coherence
    good = frf.coherence >= g
    each = f" of {frf.nperseg} samples" if frf.method == "welch" else " (adjacent bins)"
    print(f"H1 estimate {args.input} -> {args.output} ({how}): {frf.freq_hz.size} "
          f"frequencies {frf.freq_hz[0]:.4g}..{frf.freq_hz[-1]:.4g} Hz, resolution "
          f"{frf.resolution_hz:.4g} Hz, {frf.n_averages} averages{each}; "
          f"coherence >= {g:g} at {int(good.sum())} of them")
    out = Path(args.out)
    writers = table_writers(out, frf.to_columns(), sidecar)
    if args.plot is not None:
        from ehss.plots import DPI, bode_compare

        fig = bode_compare(frf, None, band_hz=band, min_coherence=g,
                           title=f"{rec.path.name}: {args.input} → {args.output}")
        writers[Path(args.plot)] = lambda tmp: fig.savefig(tmp, dpi=DPI, format="png",
                                                           bbox_inches="tight")
    write_outputs(writers)
    return 0
