"""Identify every channel of every record of an archive the same way.

Each record is one task of the campaign engine (:mod:`ehss.campaign.engine`): its
channels are read, and each goes through the identification workflow
(:func:`ehss.workflow.identify`: prepare, estimate, assess, judge) with the settings
of :class:`BatchSettings`. A task writes one row per channel — record time, orders,
fits, verdict, validated band, coefficients and the figures of
:func:`ehss.campaign.figures.loop_figures` — and each accepted-or-not model as JSON in
``models/`` beside the rows. A channel that cannot be identified (a column the record
lacks, a record too short) gets a row with its error; the other channels go on.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ehss._checks import check_band, check_choice, check_int, check_real, show
from ehss.campaign.engine import (
    Task,
    error_line,
    read_results,
    run_campaign,
)
from ehss.campaign.figures import loop_figures
from ehss.campaign.outliers import OutlierRule
from ehss.campaign.records import (
    Channel,
    Record,
    channel_pairs,
    discover,
    read_channel,
    record_columns,
    record_time,
)
from ehss.errors import DataError, ParameterError
from ehss.workflow import (
    DEFAULT_METHOD,
    Acceptance,
    Estimation,
    Identification,
    Preparation,
    identify,
)

if TYPE_CHECKING:
    import polars as pl

__all__ = ["BatchSettings", "load_manifest", "batch", "batch_task", "MODELS_FOLDER"]

#: Folder of the model files inside a campaign's output folder.
MODELS_FOLDER = "models"
_DEFAULT_ORDERS = (4, 3, 4, 1)


@dataclass(frozen=True, kw_only=True)
class BatchSettings:
    """How a batch campaign reads its records and identifies their channels.

    Attributes
    ----------
    records : tuple of str
        Globs or files (relative to the manifest's folder when read from one).
    channels : tuple of Channel
        Input/output column pairs; empty: from each record's columns
        (:func:`ehss.campaign.records.channel_pairs`).
    time_column : str or None, default "t"
        The records' time column (gives the sample rate when present).
    fs : float, optional
        Sample rate, Hz, for records without a time column or stored rate.
    orders : (na, nb, nc, delay), default (4, 3, 4, 1)
        The same for every channel, so that the figures compare over the campaign
        (``ehss order`` on a typical record helps to choose them).
    method : str, default "armax"
    band_hz : (float, float), optional
        Band of interest; default everywhere the coherence allows.
    holdout, detrend, decimate
        As :func:`ehss.workflow.identify` takes them.
    acceptance : Acceptance
    outliers : OutlierRule
    seed : int, default 0
        Campaign seed (the workflow itself draws no random numbers; kept for the
        record and for estimators that may).
    """

    records: tuple[str, ...] = ()
    channels: tuple[Channel, ...] = ()
    time_column: str | None = "t"
    fs: float | None = None
    orders: tuple[int, int, int, int] = _DEFAULT_ORDERS
    method: str = DEFAULT_METHOD
    band_hz: tuple[float, float] | None = None
    holdout: float = 0.3
    detrend: str | None = "mean"
    decimate: int | str | None = "auto"
    acceptance: Acceptance = field(default_factory=Acceptance)
    outliers: OutlierRule = field(default_factory=OutlierRule)
    seed: int = 0

    def __post_init__(self) -> None:
        from ehss.identification import METHODS

        check_choice(self.method, "method", METHODS)
        if len(self.orders) != 4:
            raise ParameterError(f"orders={list(self.orders)} must be [na, nb, nc, delay]")
        for name, v in zip(("na", "nb", "nc", "delay"), self.orders, strict=True):
            check_int(v, f"orders {name}", lo=1 if name == "na" else 0)
        check_real(self.holdout, "holdout", lo=0.0, hi=1.0, lo_open=True, hi_open=True)
        if self.fs is not None:
            check_real(self.fs, "fs", lo=0.0, lo_open=True, unit="Hz")
        check_int(self.seed, "seed", lo=0)
        if self.time_column is not None and not isinstance(self.time_column, str):
            raise ParameterError(f"time_column={show(self.time_column)} must be a column "
                                 "name")
        if self.band_hz is not None:
            check_band(self.band_hz, "band_hz")
        check_choice(self.detrend, "detrend", ("mean", "linear", None))
        if self.decimate not in ("auto", None):
            check_int(self.decimate, "decimate", lo=1)

    def summary(self) -> dict[str, Any]:
        """Plain values for JSON."""
        return to_plain(self)


def to_plain(obj: Any) -> Any:
    """Dataclasses, tuples and paths as JSON-able dicts, lists and strings."""
    if dataclasses.is_dataclass(obj):
        return {f.name: to_plain(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, (list, tuple)):
        return [to_plain(v) for v in obj]
    return obj


_TOP = {"records", "channels", "time_column", "fs", "seed", "workflow", "acceptance",
        "outliers"}
_WORKFLOW = {"orders", "method", "band_hz", "holdout", "detrend", "decimate"}


def _table(doc: dict, name: str, accepted: set[str], where: str) -> dict:
    value = doc.get(name, {})
    if not isinstance(value, dict):
        raise ParameterError(f"{where}: [{name}] must be a table")
    unknown = sorted(set(value) - accepted)
    if unknown:
        raise ParameterError(f"{where}: unknown key(s) {unknown} in [{name}]; accepted: "
                             f"{', '.join(sorted(accepted))}")
    return value


def _channels(doc: dict, where: str) -> tuple[Channel, ...]:
    out = []
    channels = doc.get("channels", [])
    if not isinstance(channels, list):
        raise ParameterError(f"{where}: 'channels' must be [[channels]] tables, got "
                             f"{show(channels)}")
    for i, c in enumerate(channels):
        if not (isinstance(c, dict) and {"input", "output"} <= set(c)
                and set(c) <= {"name", "input", "output"}):
            raise ParameterError(f"{where}: [[channels]] entry {i + 1} must have input, "
                                 "output and optionally name (column names)")
        out.append(Channel(str(c.get("name", i + 1)), str(c["input"]), str(c["output"])))
    return tuple(out)


def load_manifest(
    path: str | Path | None,
    *,
    orders: tuple[int, int, int, int] | None = None,
    method: str | None = None,
    fs: float | None = None,
    band_hz: tuple[float, float] | None = None,
) -> BatchSettings:
    """Batch settings from a TOML manifest (None: the defaults); the keywords given (not
    None) replace the manifest's values, as the command line's options do.

    Layout (every key optional)::

        records = ["2026/*.h5", "extra/run7.csv"]   # globs, relative to this file
        time_column = "t"
        fs = 1000.0
        seed = 0
        [[channels]]                  # repeat per channel; default ref<k>/fb<k> pairs
        name = "1"
        input = "ref1"
        output = "fb1"
        [workflow]
        orders = [4, 3, 4, 1]
        method = "armax"
        band_hz = [2.0, 100.0]
        holdout = 0.3
        detrend = "mean"              # or "linear", "none"
        decimate = "auto"             # or a factor, "none"
        [acceptance]                  # ehss.workflow.Acceptance
        min_fit_pct = 90.0
        [outliers]
        alpha = 0.001
        window = 15

    Raises
    ------
    DataError
        If the file is missing or not TOML.
    ParameterError
        For an unknown key or a bad value.
    """
    kwargs: dict[str, Any] = {}
    if path is not None:
        doc, where = _read_toml(path)
        unknown = sorted(set(doc) - _TOP)
        if unknown:
            raise ParameterError(f"{where}: unknown key(s) {unknown}; accepted: "
                                 f"{', '.join(sorted(_TOP))}")
        wf = _table(doc, "workflow", _WORKFLOW, where)
        acc_fields = {f.name for f in dataclasses.fields(Acceptance)}
        out_fields = {f.name for f in dataclasses.fields(OutlierRule)}
        kwargs = {k: doc[k] for k in ("time_column", "fs", "seed") if k in doc}
        root = Path(path).parent
        records = doc.get("records", [])
        if not isinstance(records, list) or not all(isinstance(r, str) for r in records):
            raise ParameterError(f"{where}: 'records' must be a list of files or globs, "
                                 f"got {show(records)}")
        kwargs["records"] = tuple(str(root / r) for r in records)
        kwargs["channels"] = _channels(doc, where)
        kwargs.update({k: tuple(v) if isinstance(v, list) else None if v == "none" else v
                       for k, v in wf.items()})
        try:
            kwargs["acceptance"] = Acceptance(**_table(doc, "acceptance", acc_fields, where))
            kwargs["outliers"] = OutlierRule(**_table(doc, "outliers", out_fields, where))
        except TypeError as exc:
            raise ParameterError(f"{where}: {exc}") from None
    given = {"orders": orders, "method": method, "fs": fs, "band_hz": band_hz}
    kwargs.update({k: v for k, v in given.items() if v is not None})
    try:
        return BatchSettings(**kwargs)
    except TypeError as exc:  # a value of the file that is not of its kind
        if path is None:
            raise
        raise ParameterError(f"{where}: {exc}") from None


def _read_toml(path: str | Path) -> tuple[dict, str]:
    where = str(path)
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh), where
    except FileNotFoundError:
        raise DataError(f"{where!r}: no such file") from None
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise DataError(f"{where!r}: not a readable TOML file: {exc}") from None


# ------------------------------------------------------------------------- the task


def _model_rows(ident: Identification) -> dict[str, Any]:
    """The row of one identified channel: orders, fits, verdict, band, coefficients,
    figures."""
    model, rep = ident.model, ident.report
    e = rep.frf_error
    band = model.band_hz or (math.nan, math.nan)
    na, nb, nc, d = ident.orders
    return {
        "method": ident.method, "na": na, "nb": nb, "nc": nc, "delay": d,
        "fs_model_hz": ident.prepared.fs_model,
        "fit_pct": float(rep.fit_pct), "stable": bool(rep.stable),
        "max_pole_radius": float(rep.max_pole_radius),
        "frf_max_magnitude_db": math.nan if e is None else float(e.max_magnitude_db),
        "frf_max_phase_deg": math.nan if e is None else float(e.max_phase_deg),
        "accepted": bool(ident.accepted),
        "verdict": "meets the acceptance" if ident.accepted else "; ".join(
            ident.verdict.failed),
        "band_lo_hz": float(band[0]), "band_hi_hz": float(band[1]),
        "a": [float(v) for v in model.a], "b": [float(v) for v in model.b],
        "c": [float(v) for v in model.c],
        **loop_figures(model),
    }


def _channel_row(record: Record, channel: Channel, settings: BatchSettings,
                 out: Path, key: str) -> dict[str, Any]:
    u, y, fs = read_channel(record, channel, time_column=settings.time_column,
                            fs=settings.fs)
    ident = identify(u, y, fs=fs, orders=settings.orders,
                     preparation=Preparation(validation=settings.holdout,
                                             band_hz=settings.band_hz,
                                             detrend=settings.detrend,
                                             decimate=settings.decimate),
                     estimation=Estimation(method=settings.method),
                     acceptance=settings.acceptance)
    name = f"{key}_{channel.name}.json"
    folder = out / MODELS_FOLDER
    folder.mkdir(exist_ok=True)
    model = dataclasses.replace(ident.model, meta={**ident.model.meta,
                                                   "record": record.name,
                                                   "channel": channel.name})
    model.save_json(folder / name)
    return {"fs_hz": fs, "n_samples": int(u.size), **_model_rows(ident),
            "model_file": f"{MODELS_FOLDER}/{name}"}


def batch_task(payload: tuple[Record, BatchSettings], seed: np.random.SeedSequence,
               out: Path) -> list[dict[str, Any]]:
    """The task of one record: one row per channel (see the module's description).

    A record that cannot be read at all raises (the engine records one error row); a
    channel that fails gets its own error row beside the others.
    """
    import warnings

    record, settings = payload
    if not Path(record.path).is_file():
        raise DataError(f"{record.path!r}: no such file")
    when, source = record_time(record)
    channels = settings.channels or tuple(channel_pairs(record_columns(record)))
    rows = []
    for channel in channels:
        head = {"channel": channel.name, "input": channel.input, "output": channel.output,
                "record_time": when, "time_source": source}
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # the verdict and the row say it all
                rows.append({**head, **_channel_row(record, channel, settings, out,
                                                    record.key)})
        except Exception as exc:  # noqa: BLE001 - one channel's failure is its row
            rows.append({**head, "status": "error", "error": error_line(exc)})
    return rows


def batch(
    records: list[str] | None = None,
    out: str | Path = "campaign",
    *,
    manifest: str | Path | None = None,
    settings: BatchSettings | None = None,
    scheduler: str | None = None,
    workers: int | None = None,
    summary: bool = True,
    quiet: bool = True,
    connect_timeout_s: float = 5.0,
) -> pl.DataFrame:
    """Identify every channel of every record; results as a polars DataFrame.

    Parameters
    ----------
    records : list of str, optional
        Globs or files; default the manifest's ``records``.
    out : str or Path
        Campaign folder: ``tasks/*.parquet`` (the rows, one file per record),
        ``models/*.json``, ``settings.json`` and ``summary.html``.
    manifest : str or Path, optional
        TOML manifest (:func:`load_manifest`); ``settings`` instead for a ready one.
    scheduler, workers, quiet, connect_timeout_s
        See :func:`ehss.campaign.engine.run_campaign`.
    summary : bool, default True
        Write ``summary.html`` (trends and flagged records).

    Returns
    -------
    polars.DataFrame
        One row per record and channel (failed ones with ``status == "error"``), with
        the columns ``flagged`` and ``flag_reason`` of the outlier rule.
    """
    from ehss.campaign.summary import flag_campaign, write_batch_summary
    from ehss.io import write_json

    if settings is None:
        settings = load_manifest(manifest)
    patterns = list(records) if records else list(settings.records)
    if not patterns:
        raise ParameterError("no records given: name files or globs, or 'records' in the "
                             "manifest")
    found = discover(patterns)
    out = Path(out)
    # the records may grow between runs; how each is identified may not
    same = {k: v for k, v in settings.summary().items() if k != "records"}
    tasks = [Task(r.key, (r, settings), {"record": r.name}) for r in found]
    run = run_campaign(batch_task, tasks, out, seed=settings.seed, scheduler=scheduler,
                       workers=workers, quiet=quiet, connect_timeout_s=connect_timeout_s,
                       description="batch", settings=same)
    frame = flag_campaign(read_results(out, sort_by=("record", "channel")),
                          settings.outliers)
    write_json(out / "settings.json", {"settings": settings.summary(),
                                       "run": {"tasks": run.n_tasks,
                                               "skipped": run.n_skipped}})
    if summary:
        write_batch_summary(frame, out / "summary.html", settings.outliers)
    return frame
