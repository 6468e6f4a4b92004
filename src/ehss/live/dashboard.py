"""The live dashboard: a Bokeh server page, in a process of its own.

The processing hands snapshots to :meth:`Dashboard.publish`, which never blocks: the
queue to the dashboard's process holds two snapshots and a third is dropped (the page
shows the next one), so a slow or absent browser costs the processing nothing. The
page is served by Bokeh's server with BokehJS from the installed package (no CDN), on
127.0.0.1 unless asked otherwise; bound to any other address it prints a warning and
answers only pages opened with the printed ``?token=...``.

Per channel (chosen in the page): Bode magnitude and phase of the current model, the
sliding H1 estimate and the baseline; the trajectories of θ̂; tracking error and the
change figures over time; the packet counters and the alarm log for all channels. With
adaptive compensation in the session, a compensation panel: the tracking error with and
without compensation over time, the current inverse's amplitude and phase over the
band, and each channel's loads and refusals with the latest compensator events.
"""

from __future__ import annotations

import html
import ipaddress
import math
import multiprocessing as mp
import queue
import secrets
import socket
import sys
import threading
from collections.abc import Sequence
from types import SimpleNamespace
from typing import Any

import numpy as np

from ehss.errors import ParameterError
from ehss.live.snapshot import ChannelSnapshot, CompensationSnapshot, SessionSnapshot

__all__ = ["Dashboard", "compensation_columns"]


class Dashboard:
    """A Bokeh server showing the snapshots of a live session.

    Parameters
    ----------
    host : str
        Address to bind (default 127.0.0.1). Any non-loopback address prints a warning
        and requires a token.
    port : int
        Port (0: any free port; see :attr:`url`).
    """

    def __init__(self, host: str = "127.0.0.1", port: int = 0) -> None:
        try:
            ip = ipaddress.ip_address(host)
        except ValueError:
            raise ParameterError(f"--bind {host!r} must be an IP address") from None
        if not isinstance(port, int) or not 0 <= port <= 65535:
            raise ParameterError(f"port={port!r} must be in 0..65535")
        self.host = str(ip)
        self.port = port
        self.token = None if ip.is_loopback else secrets.token_urlsafe(16)
        self.skipped = 0
        self._proc: Any = None
        self._queue: Any = None

    @property
    def url(self) -> str:
        tail = "" if self.token is None else f"?token={self.token}"
        return f"http://{self.host}:{self.port}/{tail}"

    def start(self, timeout_s: float = 60.0) -> None:
        """Start the server process; returns when it listens."""
        if self.token is not None:
            print(f"ehss live: WARNING: the dashboard is exposed on {self.host}; anyone who "
                  "can reach it and knows the token sees the rig's data", file=sys.stderr)
        ctx = mp.get_context("spawn")
        self._queue = ctx.Queue(maxsize=2)
        ready = ctx.Queue()
        self._proc = ctx.Process(target=_serve, name="ehss-dashboard", daemon=True,
                                 args=(self.host, self.port, self.token, self._queue, ready))
        self._proc.start()
        try:
            got = ready.get(timeout=timeout_s)
        except queue.Empty:
            self.stop()
            raise ParameterError("the dashboard did not start") from None
        if isinstance(got, str):
            self.stop()
            raise ParameterError(f"the dashboard cannot listen on {self.host}:{self.port}: "
                                 f"{got}")
        self.port = got

    def publish(self, snapshot: SessionSnapshot) -> None:
        """Hand a snapshot over without waiting; dropped when the queue is full."""
        if self._queue is None:
            return
        try:
            self._queue.put_nowait(snapshot)
        except queue.Full:
            self.skipped += 1

    def stop(self) -> None:
        """Stop the server process."""
        if self._proc is not None:
            self._proc.terminate()
            self._proc.join(5)
            self._proc = None
        if self._queue is not None:
            self._queue.cancel_join_thread()
            self._queue.close()
            self._queue = None


# ---------------------------------------------------------------------- the page
_COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2",
           "#7f7f7f", "#bcbd22", "#17becf", "#393b79", "#637939")
_TOOLS = "pan,wheel_zoom,box_zoom,reset,save"


def _free_port(host: str) -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


def _db(h: np.ndarray | None) -> list:
    return [] if h is None else (20 * np.log10(np.maximum(np.abs(h), 1e-300))).tolist()


def _deg(h: np.ndarray | None) -> list:
    return [] if h is None else np.degrees(np.unwrap(np.angle(h))).tolist()


def _bode(f: np.ndarray, h: np.ndarray | None, keep: np.ndarray | None = None) -> dict:
    """Columns f, mag (dB), ph (degrees) of a response; empty without one."""
    if h is None:
        return dict(f=[], mag=[], ph=[])
    f, h = np.asarray(f), np.asarray(h)
    if keep is not None:
        f, h = f[keep], h[keep]
    return dict(f=f.tolist(), mag=_db(h), ph=_deg(h))


def _alarm_row(e: dict) -> str:
    word = "ALARM" if e["kind"] == "alarm" else "clear"
    return (f"<span style='color:{'#c00' if word == 'ALARM' else '#070'}'><b>{word}</b></span>"
            f" t = {e['t_s']:.2f} s &nbsp; channel {e['channel']} &nbsp; FRF "
            f"{e['frf_db']:.2f} dB, gain {e['gain_db']:+.2f} dB, pole shift "
            f"{e['pole_shift']:.3f}, dominant {e['dominant_hz']:.1f} Hz"
            f" ({', '.join(e['exceeded']) or 'below thresholds'})")


def _events_html(events: Sequence[dict]) -> str:
    rows = []
    for e in reversed([e for e in events if e["kind"] in ("alarm", "clear", "message")][-20:]):
        if e["kind"] == "message":
            rows.append(f"t = {e['t_s']:.2f} s &nbsp; channel {e['channel']}: {e['text']}")
        else:
            rows.append(_alarm_row(e))
    return "<b>Alarm log</b><br>" + ("<br>".join(rows) if rows else "no alarms")


def _stats_html(snap: SessionSnapshot) -> str:
    c, lag = snap.counters, snap.lag_ms

    def f(x: float) -> str:
        return "–" if not math.isfinite(x) else f"{x:.2f}"
    chans = " ".join(
        f"<span style='color:{'#c00' if ch.alarm else '#070'}'>{ch.name}:"
        f"{'ALARM' if ch.alarm else ('learning' if ch.learning else 'ok')}</span>"
        for ch in snap.channels)
    return (f"<b>t = {snap.t_s:.1f} s</b> &nbsp; fs {snap.fs or math.nan:g} Hz &nbsp; "
            f"{snap.rate_sps:.0f} samples/s per channel &nbsp; lag p50/p99 "
            f"{f(lag.p50)}/{f(lag.p99)} ms<br>packets {c['packets']} &nbsp; gaps "
            f"{c['gaps']} (lost {c['lost_samples']}) &nbsp; reordered {c['reordered']} &nbsp; "
            f"late {c['late']} &nbsp; malformed {c['malformed']} &nbsp; foreign "
            f"{c['foreign']} &nbsp; truncated {c['truncated']}<br>channels: {chans}")


def _compensation_html(comp: CompensationSnapshot, events: Sequence[dict]) -> str:
    """Loads and refusals per channel, and the latest compensator events."""
    rows = [f"<b>Compensation</b> ({comp.mode}, band {comp.band_hz[0]:g}–"
            f"{comp.band_hz[1]:g} Hz)"]
    for ch in comp.channels:
        why = f"; last refusal: {html.escape(ch.last_reason)}" if ch.last_reason else ""
        rows.append(f"channel {ch.name}: {ch.loads} loaded ({ch.model or 'none yet'}), "
                    f"{ch.refusals} refused{why}")
    for e in reversed([e for e in events if e["kind"].startswith("compensator")][-8:]):
        what = (_LOADED.get(e.get("model"), "loaded") if e["kind"] == "compensator" else
                "change flagged: following it" if e["kind"] == "compensator_change" else
                html.escape(e.get("text") or e["kind"]) if e["kind"] == "compensator_off" else
                html.escape(e.get("reason") or e.get("text") or e["kind"]))
        rows.append(f"t = {e['t_s']:.2f} s &nbsp; channel {e['channel']}: {what}")
    return "<br>".join(rows)


#: how a load reads in the panel, by the model it came from (default: "loaded")
_LOADED = {"correction": "correction of the running compensator loaded"}


def compensation_columns(comp: CompensationSnapshot, k: int) -> tuple[dict, dict]:
    """The compensation panel's data for channel ``k``: the tracking error columns
    (``t``, ``with``, ``without``) and the current inverse's response over the band
    (``f``, ``mag`` in dB, ``ph`` in degrees; empty before the first inverse)."""
    ch = comp.channels[k]
    error = dict(t=ch.t.tolist(), with_=ch.error_rms.tolist(),
                 without=ch.error_rms_without.tolist())
    error["with"] = error.pop("with_")
    return error, _bode(ch.freq_hz, ch.inverse)


def _bode_figures(models: Any, sources: dict) -> tuple[Any, Any]:
    """Bode magnitude and phase with the sliding H1 estimate, the baseline and the
    current model."""
    mag = models.figure(title="Bode magnitude", x_axis_type="log", height=300, width=520,
                        x_axis_label="frequency (Hz)", y_axis_label="dB", tools=_TOOLS)
    ph = models.figure(title="Bode phase", x_axis_type="log", height=300, width=520,
                       x_range=mag.x_range, x_axis_label="frequency (Hz)",
                       y_axis_label="degrees", tools=_TOOLS)
    for fig, key in ((mag, "mag"), (ph, "ph")):
        items = [
            models.LegendItem(label="H1 (sliding)", renderers=[
                fig.scatter("f", key, source=sources["h1"], size=3, color="#999999")]),
            models.LegendItem(label="baseline", renderers=[
                fig.line("f", key, source=sources["reference"], line_width=2,
                         color="#2ca02c", line_dash="dashed")]),
            models.LegendItem(label="current model", renderers=[
                fig.line("f", key, source=sources["model"], line_width=2, color="#1f77b4")]),
        ]
        fig.add_layout(models.Legend(items=items, location="bottom_left"), "center")
    return mag, ph


def _compensation_figures(models: Any, error: Any, inverse: Any) -> tuple[Any, Any, Any]:
    """Tracking error with and without compensation over time; the current inverse's
    amplitude and phase over the band."""
    err = models.figure(title="compensation: tracking error RMS (desired − feedback)",
                        height=260, width=520, x_axis_label="t (s)", y_axis_type="log",
                        tools=_TOOLS)
    err.line("t", "without", source=error, line_width=1.5, color="#7f7f7f",
             legend_label="without compensation")
    err.line("t", "with", source=error, line_width=1.5, color="#d62728",
             legend_label="with compensation")
    err.legend.location = "bottom_left"
    mag = models.figure(title="current inverse: amplitude", x_axis_type="log", height=260,
                        width=520, x_axis_label="frequency (Hz)", y_axis_label="dB",
                        tools=_TOOLS)
    mag.line("f", "mag", source=inverse, line_width=2, color="#ff7f0e")
    ph = models.figure(title="current inverse: phase", x_axis_type="log", height=260,
                       width=520, x_range=mag.x_range, x_axis_label="frequency (Hz)",
                       y_axis_label="degrees", tools=_TOOLS)
    ph.line("f", "ph", source=inverse, line_width=2, color="#ff7f0e")
    return err, mag, ph


class _Page:
    """The dashboard's models, and their update from a snapshot."""

    def __init__(self) -> None:
        from bokeh import models as bm
        from bokeh.plotting import figure

        m = SimpleNamespace(**{n: getattr(bm, n) for n in (
            "ColumnDataSource", "Div", "Legend", "LegendItem", "Select")}, figure=figure)
        cds = m.ColumnDataSource
        self.status = m.Div(text="waiting for data…", name="status", width=1100)
        self.log = m.Div(text="<b>Alarm log</b><br>no alarms", name="alarms", width=600)
        self.pick = m.Select(title="channel", value="", options=[], name="channel", width=120)
        self.bode = {key: cds(dict(f=[], mag=[], ph=[]), name=f"bode_{key}")
                     for key in ("model", "reference", "h1")}
        self.hist = cds(dict(t=[], tracking=[], frf=[]), name="history")
        self.theta = cds(dict(t=[]), name="theta")
        self.comp_error = cds(dict(t=[], without=[], **{"with": []}),
                              name="compensation_error")
        self.comp_inverse = cds(dict(f=[], mag=[], ph=[]), name="compensation_inverse")
        self.comp_log = m.Div(text="", name="compensation_log", width=1100, visible=False)
        mag, ph = _bode_figures(m, self.bode)
        self.coef = figure(title="coefficients θ̂", height=260, width=520,
                           x_axis_label="t (s)", tools=_TOOLS)
        err = figure(title="tracking error RMS (ref − fb)", height=260, width=520,
                     x_axis_label="t (s)", tools=_TOOLS)
        err.line("t", "tracking", source=self.hist, line_width=1.5, color="#d62728")
        frf = figure(title="FRF distance to the reference model (dB)", height=260, width=520,
                     x_axis_label="t (s)", tools=_TOOLS)
        frf.line("t", "frf", source=self.hist, line_width=1.5, color="#9467bd")
        c_err, c_mag, c_ph = _compensation_figures(m, self.comp_error, self.comp_inverse)
        self.comp_figures = (c_err, c_mag, c_ph)
        for fig in self.comp_figures:
            fig.visible = False
        self.theta_names: tuple[str, ...] | None = None
        from bokeh.layouts import column, row

        self.root = column(self.status, row(self.pick), row(mag, ph), row(self.coef, err),
                           row(frf, self.log), self.comp_log, row(c_err),
                           row(c_mag, c_ph))

    def update(self, snap: SessionSnapshot | None) -> None:
        if snap is None or not snap.channels:
            return
        names = [ch.name for ch in snap.channels]
        if list(self.pick.options) != names:
            self.pick.options = names
            if self.pick.value not in names:
                self.pick.value = names[0]
        k = names.index(self.pick.value) if self.pick.value in names else 0
        self.status.text = _stats_html(snap)
        self.log.text = _events_html(snap.events)
        self._update_bode(snap.channels[k])
        self._update_history(snap, k)
        if snap.compensation is not None:
            self._update_compensation(snap, k)

    def _update_bode(self, ch: ChannelSnapshot) -> None:
        f = np.asarray(ch.grid_hz)
        keep = f > 0
        self.bode["model"].data = _bode(f, ch.model, keep)
        if ch.reference is not None:
            self.bode["reference"].data = _bode(f, ch.reference, keep)
        if ch.h1 is not None and ch.h1_hz is not None and ch.band_hz is not None:
            fh = np.asarray(ch.h1_hz)
            lo, hi = ch.band_hz
            self.bode["h1"].data = _bode(fh, ch.h1, (fh >= max(lo, 1e-9)) & (fh <= hi))

    def _update_history(self, snap: SessionSnapshot, k: int) -> None:
        h = snap.history
        if not h.t.size:
            return
        names = snap.theta_names
        if self.theta_names != names:
            self.theta_names = names
            for i, n in enumerate(names):
                self.coef.line("t", n, source=self.theta, legend_label=n,
                               color=_COLORS[i % len(_COLORS)], line_width=1.5)
            legend = self.coef.legend[0]
            legend.label_text_font_size = "8pt"
            legend.spacing = 0
            legend.ncols = 2
            self.coef.add_layout(legend, "right")
        th = h.theta[:, k, :]
        self.theta.data = {"t": h.t.tolist(), **{n: th[:, i].tolist()
                                                 for i, n in enumerate(names)}}
        self.hist.data = dict(t=h.t.tolist(), tracking=h.tracking[:, k].tolist(),
                              frf=h.figures[:, k, 0].tolist())

    def _update_compensation(self, snap: SessionSnapshot, k: int) -> None:
        comp = snap.compensation
        assert comp is not None
        if not self.comp_log.visible:
            self.comp_log.visible = True
            for fig in self.comp_figures:
                fig.visible = True
        self.comp_error.data, self.comp_inverse.data = compensation_columns(comp, k)
        self.comp_log.text = _compensation_html(comp, snap.events)


def _token_ok(doc: Any, token: str | None) -> bool:
    if token is None:
        return True
    given = doc.session_context.request.arguments.get("token", [b""])[0]
    return secrets.compare_digest(given, token.encode())


def _make_document(doc: Any, latest: dict, token: str | None) -> None:
    from bokeh.models.widgets.markups import Div

    doc.title = "ehss live"
    if not _token_ok(doc, token):
        doc.add_root(Div(text="ehss live: a token is required (see the command's output)",
                         name="status"))
        return
    page = _Page()
    doc.add_root(page.root)
    doc.add_periodic_callback(lambda: page.update(latest.get("snap")), 500)


def _serve(host: str, port: int, token: str | None, snapshots: Any, ready: Any) -> None:
    """Entry point of the dashboard's process."""
    import logging

    # the server's access log would fill the terminal (or a pipe nobody reads)
    for name in ("bokeh", "tornado"):
        logging.getLogger(name).setLevel(logging.WARNING)
    try:
        from bokeh.application import Application
        from bokeh.application.handlers.function import FunctionHandler
        from bokeh.server.server import Server
        from tornado.ioloop import IOLoop

        latest: dict = {}

        def reader() -> None:
            while True:
                snap = snapshots.get()
                if snap is None:
                    return
                latest["snap"] = snap

        threading.Thread(target=reader, daemon=True).start()
        port = port or _free_port(host)
        origins = [f"{host}:{port}"] + ([f"localhost:{port}"] if host == "127.0.0.1" else [])
        app = Application(FunctionHandler(lambda doc: _make_document(doc, latest, token)))
        server = Server({"/": app}, address=host, port=port, allow_websocket_origin=origins,
                        io_loop=IOLoop.current())
        server.start()
    except Exception as exc:  # reported to the parent, which stops with one line
        ready.put(str(exc))
        return
    ready.put(port)
    server.io_loop.start()
