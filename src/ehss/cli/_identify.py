"""``ehss identify``: identify a model of a loop from a record, validate it, give the verdict.

A thin adapter over :func:`ehss.workflow.identify`, the workflow the report and
``ehss order`` use too, so the verdict printed here is the library's.
"""

from __future__ import annotations

import argparse
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ehss.cli import add_command
from ehss.cli._dataargs import (
    add_record_arguments,
    load_record,
    load_validation,
    report_warnings,
    write_outputs,
)
from ehss.cli._options import add_options, build_options
from ehss.cli._outputs import InputFile, OutputFile
from ehss.errors import IdentificationError, ParameterError

if TYPE_CHECKING:
    from collections.abc import Callable

    from matplotlib.figure import Figure

    from ehss.cli._dataargs import Record
    from ehss.identification import ArmaxModel
    from ehss.workflow import Acceptance, Estimation, Evaluation, Identification, Preparation

__all__ = ["register", "run", "time_plot_path", "plot_window_s", "model_to_mat",
           "PLOT_SAMPLES"]

#: The time comparison shows at most this many samples of the validation data.
PLOT_SAMPLES = 2000


def register(sub: argparse._SubParsersAction) -> None:
    from ehss.workflow import Acceptance, Estimation, Evaluation, Preparation

    p = add_command(
        sub, "identify",
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
    add_options(p, Estimation)
    add_options(p, Preparation)
    p.add_argument("--validate", metavar="FILE", type=InputFile,
                   help="validate on this separate record instead (same column options "
                   "and sample rate as DATA)")
    add_options(p, Acceptance)
    add_options(p, Evaluation)
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


@dataclass(frozen=True)
class _Settings:
    """What ``ehss identify`` was asked for, as the library's settings objects."""

    preparation: Preparation
    estimation: Estimation
    evaluation: Evaluation
    acceptance: Acceptance


def _settings(args: argparse.Namespace, validation: tuple[Any, Any] | None) -> _Settings:
    """The settings from the flags; ``validation`` is the separate record, if any."""
    from ehss.workflow import Acceptance, Estimation, Evaluation, Preparation

    given = {} if validation is None else {"validation": validation}
    return _Settings(preparation=build_options(args, Preparation, **given),
                     estimation=build_options(args, Estimation),
                     evaluation=build_options(args, Evaluation),
                     acceptance=build_options(args, Acceptance))


def _check_args(args: argparse.Namespace) -> None:
    """What can be checked before the record is read (the settings' own values are
    checked again by :func:`_settings`)."""
    if args.validate is not None and args.holdout is not None:
        raise ParameterError("give either --holdout or --validate, not both")
    for name in ("na", "nb", "nc", "delay"):
        v = getattr(args, name)
        if v < (1 if name == "na" else 0):
            raise ParameterError(f"--{name} {v} must be >= {1 if name == 'na' else 0}")
    suffix = Path(args.out).suffix.lower()
    if suffix not in (".json", ".mat"):
        raise ParameterError(f"--out {args.out}: the model is written as .json or .mat, "
                             f"not {suffix or 'a file without a suffix'}")
    _settings(args, None)


def run(args: argparse.Namespace) -> int:
    from ehss.workflow import identify

    _check_args(args)
    rec = load_record(args)
    val_rec = load_validation(args, rec)
    opts = _settings(args, None if val_rec is None else (val_rec.u, val_rec.y))
    from rich.console import Console

    with report_warnings("identify"):
        # a spinner on a terminal while the model is fitted and validated, nothing otherwise
        with Console(stderr=True).status(
                f"fitting {args.method} ({args.na},{args.nb},{args.nc}) to "
                f"{rec.u.size} samples and validating it"):
            res = identify(
                rec.u, rec.y, fs=rec.fs, orders=(args.na, args.nb, args.nc, args.delay),
                preparation=opts.preparation, estimation=opts.estimation,
                evaluation=opts.evaluation, acceptance=opts.acceptance,
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
        _plots(res, rec, args, writers)
    write_outputs(writers)
    return 0


def model_to_mat(path: Path, model: ArmaxModel, doc: dict[str, Any]) -> None:
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


def _jsonable(doc: dict[str, Any]) -> Any:
    from ehss.io.writers import to_jsonable

    return to_jsonable(doc)


def _plots(res: Identification, rec: Record, args: argparse.Namespace,
           writers: dict[Path, Callable[[Path], None]]) -> None:
    from ehss.plots import DPI, bode_compare, time_compare

    model, rep, prep = res.model, res.report, res.prepared
    fs_m = prep.fs_model
    band = prep.band_hz if prep.band_hz is not None else (0.0, 0.45 * fs_m)
    title = (f"{rec.path.name}: {args.input} → {args.output}, {res.method} "
             f"({model.na},{model.nb},{model.nc}) d={model.delay}")
    bode = bode_compare(rep.frf, {"identified model": model}, band_hz=band,
                        min_coherence=res.verdict.acceptance.min_coherence, title=title)
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

    def saver(fig: Figure) -> Callable[[Path], None]:
        return lambda tmp: fig.savefig(tmp, dpi=DPI, format="png", bbox_inches="tight")

    writers[Path(args.plot)] = saver(bode)
    writers[time_plot_path(args.plot)] = saver(tfig)


def _fit(v: float) -> str:
    from ehss.validation import fit_text

    return fit_text(v)


def _provenance(rec: Record, val_rec: Record | None, args: argparse.Namespace,
                opts: _Settings) -> dict[str, Any]:
    from ehss._provenance import versions

    band = opts.preparation.band_hz
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
            "method": opts.estimation.method, "init": opts.estimation.init,
            "holdout": opts.preparation.holdout,
            "band_hz": None if band is None else list(band),
            "min_coherence": opts.acceptance.min_coherence,
            "nperseg": opts.evaluation.nperseg,
            "frf_method": opts.evaluation.frf_method,
            "detrend": opts.preparation.detrend,
            "decimate": opts.preparation.decimate,
            "initial": opts.evaluation.initial,
        },
        "versions": versions(),
    }


def _print_model(res: Identification, rec: Record, args: argparse.Namespace) -> None:
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
