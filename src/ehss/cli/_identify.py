"""``ehss identify``: identify a model of a loop from a record, validate it, give the verdict.

A thin adapter over :func:`ehss.workflow.identify`, the workflow the report and
``ehss order`` use too, so the verdict printed here is the library's.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from ehss._checks import check_band
from ehss.cli import command_help
from ehss.cli._dataargs import (
    add_record_arguments,
    load_record,
    load_validation,
    report_warnings,
    write_outputs,
)
from ehss.cli._outputs import InputFile, OutputFile
from ehss.errors import IdentificationError, ParameterError

__all__ = ["register", "run", "time_plot_path", "plot_window_s", "model_to_mat",
           "PLOT_SAMPLES"]

#: The time comparison shows at most this many samples of the validation data.
PLOT_SAMPLES = 2000


def register(sub: argparse._SubParsersAction) -> None:
    from ehss.identification import INITS, METHODS
    from ehss.workflow import DEFAULT_METHOD

    p = sub.add_parser(
        "identify",
        help=command_help("identify"),
        description="Identify A y = q^-d B u + C e from a record: remove the operating point "
        "(or a drift), decimate an oversampled record, fit the model, and validate it on the "
        "held-out end or on a separate record (free-run fit from the least-squares initial "
        "state, k-step prediction fit, frequency-response error where the coherence is "
        "high, residual tests). Prints the model at full precision with its poles and zeros "
        "and the verdict against the acceptance (stable, fit >= 90 %, within 1 dB / 5 deg "
        "beyond twice the estimate's own standard error where coherence >= 0.9), and saves "
        "it as JSON or MATLAB .mat. An unstable model "
        "is not written.",
        epilog="orders unknown? `ehss order DATA --input U --output Y` fits a grid of them "
        "around the record's estimated delay and prints the identify command of the best",
    )
    add_record_arguments(p)
    p.add_argument("--na", type=int, required=True, metavar="N", help="order of A (>= 1)")
    p.add_argument("--nb", type=int, required=True, metavar="N",
                   help="order of B (b0..b_nb, >= 0)")
    p.add_argument("--nc", type=int, required=True, metavar="N",
                   help="order of C (>= 0; ignored by arx)")
    p.add_argument("--delay", type=int, default=1, metavar="D",
                   help="input delay in samples (default: %(default)s)")
    p.add_argument("--method", choices=METHODS, default=DEFAULT_METHOD,
                   help="estimator: arx = least squares; armax = prediction-error "
                   "minimisation started from extended least squares; rels = the paper's "
                   "recursive extended least squares (eqs 19-22); rml = recursive maximum "
                   "likelihood (default: %(default)s)")
    p.add_argument("--init", choices=INITS, default="batch",
                   help="start of rels/rml: from the batch (armax) estimate, or the paper's "
                   "zero start (default: %(default)s; ignored by the batch methods)")
    p.add_argument("--holdout", type=float, metavar="FRACTION",
                   help="fraction at the end of the record kept for validation "
                   "(default: 0.3, or none with --validate)")
    p.add_argument("--validate", metavar="FILE", type=InputFile,
                   help="validate on this separate record instead (same column options "
                   "and sample rate as DATA)")
    p.add_argument("--band", nargs=2, type=float, metavar=("LO", "HI"),
                   help="band of interest (Hz): where the frequency response is compared, "
                   "the fit is scored and the decimation aims (default: up to 0.45 fs)")
    p.add_argument("--min-coherence", type=float, default=0.9, metavar="G2",
                   help="points of the validation's frequency response with a lower "
                   "coherence are not compared (default: %(default)s)")
    p.add_argument("--nperseg", type=int, metavar="N",
                   help="segment length of the validation's frequency-response estimate, "
                   "in samples at the model's rate (default: from the record's length and "
                   "the band, at least 8 averages)")
    p.add_argument("--frf-method", choices=("auto", "welch", "dft"), default="auto",
                   help="validation's frequency response: Welch H1, whole-record DFT (for "
                   "sweeps), or whichever validates more of the band (default: %(default)s)")
    p.add_argument("--detrend", choices=("mean", "linear", "none"), default="mean",
                   help="remove the mean (operating point) or a straight line from the "
                   "estimation and the validation data (default: %(default)s)")
    p.add_argument("--decimate", default="auto", metavar="auto|none|N",
                   help="decimate an oversampled record by N (zero-phase anti-alias "
                   "filter) before identifying; auto: to about 10 times the highest "
                   "frequency of interest; the model is then at the decimated rate "
                   "(default: %(default)s)")
    p.add_argument("--initial", choices=("estimate", "zero"), default="estimate",
                   help="initial state of the validation simulation: least-squares "
                   "estimate or rest (default: %(default)s)")
    p.add_argument("--out", required=True, metavar="MODEL.json|MODEL.mat", type=OutputFile,
                   help="model file to write: JSON, or .mat with A, B, C, num, den, nk, Ts, "
                   "offsets and band for MATLAB")
    p.add_argument("--plot", metavar="BODE.png", type=OutputFile,
                   help="write the Bode comparison there, and the time comparison beside it "
                   "(BODE_time.png)")
    p.set_defaults(func=run, derived_outputs=lambda a: [time_plot_path(a.plot)] if a.plot
                   else [])


def time_plot_path(plot: str | Path) -> Path:
    """Where the time comparison goes for ``--plot plot``: ``<stem>_time<suffix>``."""
    plot = Path(plot)
    return plot.with_name(f"{plot.stem}_time{plot.suffix or '.png'}")


def plot_window_s(n_validation: int, fs: float) -> float:
    """End (s) of the time comparison's window: the validation data from its start, at
    most :data:`PLOT_SAMPLES` of it, so the window follows the record's rate and length
    (300 s of a 1 Hz record, 2 s of a 1 kHz rig)."""
    return (min(int(n_validation), PLOT_SAMPLES) - 1) / float(fs)


def _decimate_arg(text: str) -> int | str | None:
    t = text.strip().lower()
    if t == "auto":
        return "auto"
    if t == "none":
        return None
    try:
        q = int(t)
    except ValueError:
        raise ParameterError(f"--decimate {text!r} must be auto, none or an integer >= 1") \
            from None
    if q < 1:
        raise ParameterError(f"--decimate {q} must be auto, none or an integer >= 1")
    return q


def _check_args(args: argparse.Namespace) -> dict[str, Any]:
    if args.validate is not None and args.holdout is not None:
        raise ParameterError("give either --holdout or --validate, not both")
    holdout = 0.3 if args.holdout is None else args.holdout
    if args.validate is None and not (math.isfinite(holdout) and 0.0 < holdout < 1.0):
        raise ParameterError(f"--holdout {holdout} must be in (0, 1): identify validates on "
                             "held-out data (or give --validate FILE)")
    band = None if args.band is None else check_band(args.band, "--band")
    if not 0.0 <= args.min_coherence <= 1.0:
        raise ParameterError(f"--min-coherence {args.min_coherence} must be in [0, 1]")
    if args.nperseg is not None and args.nperseg < 8:
        raise ParameterError(f"--nperseg {args.nperseg} must be >= 8")
    for name in ("na", "nb", "nc", "delay"):
        v = getattr(args, name)
        if v < (1 if name == "na" else 0):
            raise ParameterError(f"--{name} {v} must be >= {1 if name == 'na' else 0}")
    suffix = Path(args.out).suffix.lower()
    if suffix not in (".json", ".mat"):
        raise ParameterError(f"--out {args.out}: the model is written as .json or .mat, "
                             f"not {suffix or 'a file without a suffix'}")
    return {"holdout": holdout, "band": band, "decimate": _decimate_arg(args.decimate),
            "detrend": None if args.detrend == "none" else args.detrend}


def run(args: argparse.Namespace) -> int:
    from ehss.workflow import Acceptance, identify

    opts = _check_args(args)
    plots = (args.plot, None if args.plot is None else time_plot_path(args.plot))
    rec = load_record(args)
    val_rec = load_validation(args, rec)
    validation: Any = opts["holdout"] if val_rec is None else (val_rec.u, val_rec.y)
    from rich.console import Console

    with report_warnings("identify"):
        # a spinner on a terminal while the model is fitted and validated, nothing otherwise
        with Console(stderr=True).status(
                f"fitting {args.method} ({args.na},{args.nb},{args.nc}) to "
                f"{rec.u.size} samples and validating it"):
            res = identify(
                rec.u, rec.y, fs=rec.fs, orders=(args.na, args.nb, args.nc, args.delay),
                method=args.method, init=args.init, validation=validation,
                band_hz=opts["band"], detrend=opts["detrend"], decimate=opts["decimate"],
                nperseg=args.nperseg, frf_method=args.frf_method, initial=args.initial,
                acceptance=Acceptance(min_coherence=args.min_coherence),
            )
        model = res.model
        _print_model(res, rec, args)
        # inside the block: an unstable model is an error, not also a warning
        if not model.is_stable():
            raise IdentificationError(
                f"the identified model is unstable (max pole radius "
                f"{model.max_pole_radius():.4f}); {args.out} not written: try other orders "
                "(ehss order), another --method or a band-limited record")
    doc = model.to_dict()
    doc["identification"] = res.summary()
    doc["validation"] = res.report.summary()
    doc["verdict"] = res.verdict.summary()
    doc["provenance"] = _provenance(rec, val_rec, args, opts)

    from ehss.io.writers import to_jsonable

    writers: dict[Path, Any] = {}
    out = Path(args.out)
    if out.suffix.lower() == ".mat":
        writers[out] = lambda tmp: model_to_mat(tmp, model, doc)
    else:
        writers[out] = lambda tmp: tmp.write_text(
            json.dumps(to_jsonable(doc), indent=2, allow_nan=False) + "\n", encoding="utf-8")
    if args.plot is not None:
        _plots(res, rec, args, plots, writers)
    write_outputs(writers)
    return 0


def model_to_mat(path: Path, model, doc: dict[str, Any]) -> None:
    """Write ``model`` as MATLAB variables (see ``ehss identify --help``).

    ``A``, ``B``, ``C`` are the polynomials in z^-1 as MATLAB's ``idpoly(A, B, C, 1, 1,
    NoiseVariance, Ts)`` takes them (``B`` with ``nk`` leading zeros for the delay), so
    ``idpoly(A, B, C, 1, 1, NoiseVariance, Ts)`` or ``tf(num, den, Ts, 'Variable',
    'z^-1')`` rebuilds the model; ``b`` holds B without the delay's zeros.
    """
    import scipy.io

    b_full = np.concatenate([np.zeros(model.delay), model.b])
    nan = float("nan")
    off = model.offsets if model.offsets is not None else (nan, nan)
    band = model.band_hz if model.band_hz is not None else (nan, nan)
    variables = {
        "A": model.a.reshape(1, -1),
        "B": b_full.reshape(1, -1),
        "C": model.c.reshape(1, -1),
        "num": b_full.reshape(1, -1),
        "den": model.a.reshape(1, -1),
        "b": model.b.reshape(1, -1),
        "na": float(model.na), "nb": float(model.nb + 1), "nc": float(model.nc),
        "nk": float(model.delay),
        "Ts": float(model.dt),
        "fs_hz": float(model.fs),
        "NoiseVariance": float(model.noise_variance),
        "offsets": np.array([[off[0], off[1]]]),
        "u0": float(off[0]), "y0": float(off[1]),
        "band_hz": np.array([[band[0], band[1]]]),
        "method": str(doc["identification"]["method"]),
        "accepted": bool(doc["verdict"]["accepted"]),
        "ehss_json": json.dumps(_jsonable(doc), allow_nan=True),
    }
    with open(path, "wb") as fh:
        scipy.io.savemat(fh, variables, do_compression=True, oned_as="row")


def _jsonable(doc):
    from ehss.io.writers import to_jsonable

    return to_jsonable(doc)


def _plots(res, rec, args, plots, writers) -> None:
    from ehss.plots import DPI, bode_compare, time_compare

    model, rep, prep = res.model, res.report, res.prepared
    fs_m = prep.fs_model
    band = prep.band_hz if prep.band_hz is not None else (0.0, 0.45 * fs_m)
    title = (f"{rec.path.name}: {args.input} → {args.output}, {res.method} "
             f"({model.na},{model.nb},{model.nc}) d={model.delay}")
    bode = bode_compare(rep.frf, {"identified model": model}, band_hz=band,
                        min_coherence=args.min_coherence, title=title)
    t = np.arange(prep.y_val.size) / fs_m
    # back to the validation record's own level (and drift), as measured
    tr = prep.trend_y_val
    k = np.arange(t.size) * prep.decimation
    trend = tr.offset + tr.slope * (k - (k[-1] if k.size else 0) / 2.0)
    where = "separate record" if prep.separate_validation else "held-out data"
    tfig = time_compare(t, prep.y_val + trend, {"model (simulated)": rep.simulated + trend},
                        window_s=(0.0, plot_window_s(rep.n_validation, fs_m)),
                        ylabel=args.output,
                        title=f"{where}, simulation fit {_fit(rep.simulation_fit_pct)}")

    def saver(fig):
        return lambda tmp: fig.savefig(tmp, dpi=DPI, format="png", bbox_inches="tight")

    writers[Path(plots[0])] = saver(bode)
    writers[Path(plots[1])] = saver(tfig)


def _fit(v: float) -> str:
    from ehss.validation import fit_text

    return fit_text(v)


def _provenance(rec, val_rec, args, opts) -> dict[str, Any]:
    from ehss._provenance import versions

    return {
        "command": "ehss identify",
        "input_file": str(rec.path),
        "validation_file": None if val_rec is None else str(val_rec.path),
        "columns": {"input": args.input, "output": args.output,
                    "time": args.time_column if args.fs is None else None},
        "fs_hz": rec.fs,
        "n_samples": int(rec.u.size),
        "settings": {
            "na": args.na, "nb": args.nb, "nc": args.nc, "delay": args.delay,
            "method": args.method, "init": args.init,
            "holdout": None if val_rec is not None else opts["holdout"],
            "band_hz": None if opts["band"] is None else list(opts["band"]),
            "min_coherence": args.min_coherence,
            "nperseg": args.nperseg,
            "frf_method": args.frf_method,
            "detrend": opts["detrend"],
            "decimate": opts["decimate"],
            "initial": args.initial,
        },
        "versions": versions(),
    }


def _print_model(res, rec, args) -> None:
    from rich.console import Console
    from rich.table import Table

    model, prep = res.model, res.prepared
    console = Console(width=120, highlight=False)
    from ehss.workflow import delay_text

    delay = delay_text(args.delay, decimation=prep.decimation, fs=prep.fs)
    console.print(f"{res.method.upper()} model ({model.na},{model.nb},{model.nc}), {delay}, "
                  f"dt = {model.dt!r} s, from {prep.u.size} samples of "
                  f"{rec.path.name} ({args.input} → {args.output})")
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
    console.print(f"dc gain = {model.dc_gain()!r}")
    console.print(res.format(), soft_wrap=True)


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
