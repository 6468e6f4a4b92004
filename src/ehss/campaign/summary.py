"""Summaries of campaigns: flagged records, trend plots, one self-contained HTML page.

The page embeds its figures as base64 PNG (matplotlib, Agg) and needs no network.
"""

from __future__ import annotations

import base64
import html
import io
import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ehss._files import atomic_path
from ehss.campaign.figures import FIGURE_UNITS, FIGURES
from ehss.campaign.outliers import OutlierRule, flag_outliers

if TYPE_CHECKING:
    import polars as pl
    from matplotlib.figure import Figure

__all__ = ["flag_campaign", "write_batch_summary", "write_montecarlo_summary",
           "write_trend_png", "TRENDED"]

#: Figures the outlier rule scores: the loop's own. Not the delay (fixed by the orders)
#: nor the fit (bounded and skewed: its low tail is the noise's, not the loop's; it is
#: plotted, and a model that fails the acceptance says so in its verdict).
TRENDED = ("natural_freq_hz", "damping", "dc_gain", "bandwidth_hz")


def flag_campaign(frame: pl.DataFrame, rule: OutlierRule) -> pl.DataFrame:
    """``frame`` with ``flagged`` and ``flag_reason`` per row: per channel, in record-time
    order, each figure of :data:`TRENDED` is scored by
    :func:`ehss.campaign.outliers.flag_outliers`; rows that failed are not flagged (their
    ``error`` says why)."""
    import polars as pl

    n = frame.height
    flagged = np.zeros(n, dtype=bool)
    reasons = [""] * n
    if n and "channel" in frame.columns and "record_time" in frame.columns:
        f = frame.with_row_index("_row")
        ok = f.filter(pl.col("status") == "ok")
        for (_,), part in ok.group_by(["channel"], maintain_order=True):
            part = part.sort("record_time", "record", maintain_order=True)
            values = {k: part[k].cast(pl.Float64).fill_null(math.nan).to_numpy()
                      for k in TRENDED if k in part.columns}
            flags, why, _ = flag_outliers(values, rule)
            for row, flag, text in zip(part["_row"].to_list(), flags, why, strict=True):
                flagged[row], reasons[row] = bool(flag), text
    return frame.with_columns(pl.Series("flagged", flagged),
                              pl.Series("flag_reason", reasons, dtype=pl.String))


def _png(fig: Figure) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, bbox_inches="tight")
    return base64.b64encode(buf.getvalue()).decode("ascii")


def _trend_figure(frame: pl.DataFrame, rule: OutlierRule) -> str:
    """One panel per figure: the value over record time per channel, flagged records
    ringed in red."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import polars as pl

    names = [k for k in (*FIGURES[:4], "fit_pct") if k in frame.columns]
    ok = frame.filter(pl.col("status") == "ok").sort("record_time")
    fig, axes = plt.subplots(len(names), 1, figsize=(9, 2.0 * len(names)), sharex=True,
                             squeeze=False)
    for ax, name in zip(axes[:, 0], names, strict=True):
        for (ch,), part in ok.group_by(["channel"], maintain_order=True):
            t = part["record_time"].to_list()
            ax.plot(t, part[name].to_numpy(), ".-", ms=3, lw=0.6, label=f"channel {ch}")
            bad = part["flagged"].to_numpy()
            if bad.any():
                ax.plot([t[i] for i in np.flatnonzero(bad)], part[name].to_numpy()[bad],
                        "o", mfc="none", mec="red", ms=9)
        unit = FIGURE_UNITS.get(name, "%" if name == "fit_pct" else "")
        ax.set_ylabel(f"{name}" + (f" [{unit}]" if unit else ""), fontsize=8)
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7, ncol=4, loc="best")
    axes[-1, 0].set_xlabel("record time (UTC)")
    fig.suptitle(f"Trends; red rings: flagged (family-wise false-flag rate "
                 f"{rule.alpha:g} per record and channel)", fontsize=9)
    out = _png(fig)
    plt.close(fig)
    return out


def write_trend_png(frame: pl.DataFrame, path: str | Path, rule: OutlierRule) -> Path:
    """The summary's trend plot of a campaign's rows (:func:`flag_campaign`'s output)
    as a PNG file, written whole or not at all."""
    from ehss._files import atomic_path

    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_bytes(base64.b64decode(_trend_figure(frame, rule)))
    return path


def _table_html(rows: list[list[Any]], head: list[str]) -> str:
    cells = "".join(f"<th>{html.escape(h)}</th>" for h in head)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in r) + "</tr>"
                   for r in rows)
    return f"<table><tr>{cells}</tr>{body}</table>"


_STYLE = ("<style>body{font-family:sans-serif;margin:2em;max-width:75em}"
          "table{border-collapse:collapse;font-size:90%}td,th{border:1px solid #ccc;"
          "padding:2px 6px;text-align:left}</style>")


def _write_page(path: Path, title: str, parts: list[str]) -> None:
    doc = (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(title)}"
           f"</title>{_STYLE}</head><body><h1>{html.escape(title)}</h1>"
           + "\n".join(parts) + "</body></html>\n")
    with atomic_path(path) as tmp:
        tmp.write_text(doc, encoding="utf-8")


def write_batch_summary(frame: pl.DataFrame, path: str | Path, rule: OutlierRule) -> Path:
    """The batch campaign's page: counts, the rule, trend plots, flagged records,
    failures."""
    import polars as pl

    path = Path(path)
    for name, dtype in (("record_time", pl.Datetime("us", "UTC")), ("channel", pl.String),
                        ("accepted", pl.Boolean)):
        if name not in frame.columns:  # every record failed: no such column was written
            frame = frame.with_columns(pl.lit(None, dtype=dtype).alias(name))
    ok = frame.filter(pl.col("status") == "ok")
    failed = frame.filter(pl.col("status") != "ok")
    m = len(TRENDED)
    parts = [f"<p>{frame.height} channel rows from "
             f"{frame['record'].n_unique() if frame.height else 0} records: "
             f"{ok.height} identified ({int(ok['accepted'].sum()) if ok.height else 0} "
             f"meet the acceptance), {failed.height} failed.</p>",
             f"<p>Flagging rule: per channel and figure ({', '.join(TRENDED)}), the residual "
             f"from a running median over {rule.window} records, robust z = (r − median)"
             f" / (1.4826 MAD); flagged when |z| &gt; Φ⁻¹(1 − α/(2·{m})) = "
             f"{rule.threshold(m):.2f} with α = {rule.alpha:g}: under normal residuals a "
             f"sound record is flagged with probability at most α (Bonferroni over the "
             f"{m} figures).</p>"]
    if ok.height:
        parts.append(f"<img alt='trends' src='data:image/png;base64,"
                     f"{_trend_figure(frame, rule)}'>")
    flagged = ok.filter(pl.col("flagged")).sort("record_time")
    parts.append(f"<h2>Flagged records ({flagged.height})</h2>")
    parts.append(_table_html([[r["record_time"], r["record"], r["channel"], r["flag_reason"]]
                              for r in flagged.iter_rows(named=True)],
                             ["record time", "record", "channel", "why"]))
    parts.append(f"<h2>Failures ({failed.height})</h2>")
    parts.append(_table_html([[r["record"], r.get("channel") or "", r["error"]]
                              for r in failed.iter_rows(named=True)],
                             ["record", "channel", "error"]))
    _write_page(path, "ehss batch: campaign summary", parts)
    return path


def _histograms(frame: pl.DataFrame, columns: Sequence[str]) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(columns), figsize=(3.2 * len(columns), 2.8),
                             squeeze=False)
    for ax, name in zip(axes[0], columns, strict=True):
        x = frame[name].cast(float).drop_nulls().to_numpy()
        x = x[np.isfinite(x)]
        if x.size:
            ax.hist(x, bins=min(40, max(5, x.size // 10)))
        ax.set_title(name, fontsize=8)
        ax.tick_params(labelsize=7)
    out = _png(fig)
    plt.close(fig)
    return out


def write_montecarlo_summary(frame: pl.DataFrame, path: str | Path, parameters: list[str],
                             outcome: dict[str, Any]) -> Path:
    """The Monte Carlo campaign's page: the sampled parameters' and the outcomes'
    distributions, and the fraction of samples that meet the acceptance."""
    import polars as pl

    path = Path(path)
    ok = frame.filter(pl.col("status") == "ok")
    parts = [f"<p>{frame.height} samples, {ok.height} completed, "
             f"{frame.height - ok.height} failed.</p>",
             f"<p>{html.escape(outcome['text'])}</p>"]
    if ok.height:
        parts.append(f"<h2>Sampled parameters</h2><img alt='parameters' "
                     f"src='data:image/png;base64,{_histograms(ok, parameters)}'>")
        outs = [c for c in ("error_uncompensated_pct", "error_nominal_pct", "error_own_pct",
                            "natural_freq_hz", "dc_gain") if c in ok.columns]
        parts.append(f"<h2>Outcomes</h2><img alt='outcomes' "
                     f"src='data:image/png;base64,{_histograms(ok, outs)}'>")
    failed = frame.filter(pl.col("status") != "ok")
    parts.append(f"<h2>Failures ({failed.height})</h2>")
    parts.append(_table_html([[r["task"], r["error"]] for r in failed.iter_rows(named=True)],
                             ["sample", "error"]))
    _write_page(path, "ehss montecarlo: summary", parts)
    return path
