"""The live dashboard: a Bokeh server page, in a process of its own.

The processing hands snapshots to :meth:`Dashboard.publish`, which never blocks: the
queue to the dashboard's process holds two snapshots and a third is dropped (the page
shows the next one), so a slow or absent browser costs the processing nothing. The
page is served by Bokeh's server with BokehJS from the installed package (no CDN), on
127.0.0.1 unless asked otherwise; bound to any other address it prints a warning and
answers only pages opened with the printed ``?token=...``.

Per channel (chosen in the page): Bode magnitude and phase of the current model, the
sliding H1 estimate and the baseline; the trajectories of θ̂; tracking error and the
change figures over time; the packet counters and the alarm log for all channels.
"""

from __future__ import annotations

import ipaddress
import math
import multiprocessing as mp
import queue
import secrets
import socket
import sys
import threading

import numpy as np

from ehss.errors import ParameterError

__all__ = ["Dashboard"]


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
        self._proc = None
        self._queue = None

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

    def publish(self, snapshot: dict) -> None:
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


def _free_port(host: str) -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return s.getsockname()[1]


def _db(h) -> list:
    return [] if h is None else (20 * np.log10(np.maximum(np.abs(h), 1e-300))).tolist()


def _deg(h) -> list:
    return [] if h is None else np.degrees(np.unwrap(np.angle(h))).tolist()


def _events_html(events: list[dict]) -> str:
    if not events:
        return "<b>Alarm log</b><br>no alarms"
    rows = []
    for e in reversed(events[-20:]):
        if e["kind"] == "message":
            rows.append(f"t = {e['t_s']:.2f} s &nbsp; channel {e['channel']}: {e['text']}")
            continue
        word = "ALARM" if e["kind"] == "alarm" else "clear"
        rows.append(
            f"<span style='color:{'#c00' if word == 'ALARM' else '#070'}'><b>{word}</b></span>"
            f" t = {e['t_s']:.2f} s &nbsp; channel {e['channel']} &nbsp; FRF "
            f"{e['frf_db']:.2f} dB, gain {e['gain_db']:+.2f} dB, pole shift "
            f"{e['pole_shift']:.3f}, dominant {e['dominant_hz']:.1f} Hz"
            f" ({', '.join(e['exceeded']) or 'below thresholds'})")
    return "<b>Alarm log</b><br>" + "<br>".join(rows)


def _stats_html(snap: dict) -> str:
    c, lag = snap["counters"], snap["lag_ms"]

    def f(x):
        return "–" if not math.isfinite(x) else f"{x:.2f}"
    chans = " ".join(
        f"<span style='color:{'#c00' if ch['alarm'] else '#070'}'>{ch['name']}:"
        f"{'ALARM' if ch['alarm'] else ('learning' if ch['learning'] else 'ok')}</span>"
        for ch in snap["channels"])
    return (f"<b>t = {snap['t_s']:.1f} s</b> &nbsp; fs {snap['fs']:g} Hz &nbsp; "
            f"{snap['rate_sps']:.0f} samples/s per channel &nbsp; lag p50/p99 "
            f"{f(lag['p50'])}/{f(lag['p99'])} ms<br>packets {c['packets']} &nbsp; gaps "
            f"{c['gaps']} (lost {c['lost_samples']}) &nbsp; reordered {c['reordered']} &nbsp; "
            f"late {c['late']} &nbsp; malformed {c['malformed']} &nbsp; foreign "
            f"{c['foreign']} &nbsp; truncated {c['truncated']}<br>channels: {chans}")


def _make_document(doc, latest: dict, token: str | None) -> None:
    from bokeh.layouts import column, row
    from bokeh.models import ColumnDataSource, Div, Legend, LegendItem, Select
    from bokeh.plotting import figure

    doc.title = "ehss live"
    if token is not None:
        given = doc.session_context.request.arguments.get("token", [b""])[0]
        if not secrets.compare_digest(given, token.encode()):
            doc.add_root(Div(text="ehss live: a token is required (see the command's output)",
                             name="status"))
            return
    status = Div(text="waiting for data…", name="status", width=1100)
    log = Div(text="<b>Alarm log</b><br>no alarms", name="alarms", width=600)
    pick = Select(title="channel", value="", options=[], name="channel", width=120)
    bode_model = ColumnDataSource(dict(f=[], mag=[], ph=[]), name="bode_model")
    bode_ref = ColumnDataSource(dict(f=[], mag=[], ph=[]), name="bode_reference")
    bode_h1 = ColumnDataSource(dict(f=[], mag=[], ph=[]), name="bode_h1")
    hist = ColumnDataSource(dict(t=[], tracking=[], frf=[]), name="history")
    theta = ColumnDataSource(dict(t=[]), name="theta")
    tools = "pan,wheel_zoom,box_zoom,reset,save"
    mag = figure(title="Bode magnitude", x_axis_type="log", height=300, width=520,
                 x_axis_label="frequency (Hz)", y_axis_label="dB", tools=tools)
    ph = figure(title="Bode phase", x_axis_type="log", height=300, width=520,
                x_range=mag.x_range, x_axis_label="frequency (Hz)", y_axis_label="degrees",
                tools=tools)
    for fig, key in ((mag, "mag"), (ph, "ph")):
        items = [
            LegendItem(label="H1 (sliding)", renderers=[
                fig.scatter("f", key, source=bode_h1, size=3, color="#999999")]),
            LegendItem(label="baseline", renderers=[
                fig.line("f", key, source=bode_ref, line_width=2, color="#2ca02c",
                         line_dash="dashed")]),
            LegendItem(label="current model", renderers=[
                fig.line("f", key, source=bode_model, line_width=2, color="#1f77b4")]),
        ]
        fig.add_layout(Legend(items=items, location="bottom_left"), "center")
    coef = figure(title="coefficients θ̂", height=260, width=520, x_axis_label="t (s)",
                  tools=tools)
    err = figure(title="tracking error RMS (ref − fb)", height=260, width=520,
                 x_axis_label="t (s)", tools=tools)
    err.line("t", "tracking", source=hist, line_width=1.5, color="#d62728")
    frf = figure(title="FRF distance to the reference model (dB)", height=260, width=520,
                 x_axis_label="t (s)", tools=tools)
    frf.line("t", "frf", source=hist, line_width=1.5, color="#9467bd")
    made = {"names": None}

    def update() -> None:
        snap = latest.get("snap")
        if snap is None:
            return
        names = [ch["name"] for ch in snap["channels"]]
        if pick.options != names:
            pick.options = names
            if pick.value not in names:
                pick.value = names[0]
        k = names.index(pick.value) if pick.value in names else 0
        ch = snap["channels"][k]
        status.text = _stats_html(snap)
        log.text = _events_html(snap["events"])
        f = np.asarray(ch["grid_hz"])
        keep = f > 0
        bode_model.data = dict(f=f[keep].tolist(), mag=np.array(_db(ch["model"]))[keep].tolist()
                               if ch["model"] is not None else [],
                               ph=np.array(_deg(ch["model"]))[keep].tolist()
                               if ch["model"] is not None else [])
        if ch["model"] is None:
            bode_model.data = dict(f=[], mag=[], ph=[])
        if ch["reference"] is not None:
            bode_ref.data = dict(f=f[keep].tolist(), mag=np.array(_db(ch["reference"]))[keep]
                                 .tolist(), ph=np.array(_deg(ch["reference"]))[keep].tolist())
        if ch["h1"] is not None and ch["band_hz"] is not None:
            fh = np.asarray(ch["h1_hz"])
            lo, hi = ch["band_hz"]
            sel = (fh >= max(lo, 1e-9)) & (fh <= hi)
            h1 = np.asarray(ch["h1"])[sel]
            bode_h1.data = dict(f=fh[sel].tolist(), mag=_db(h1), ph=_deg(h1))
        h = snap["history"]
        t = np.asarray(h["t"])
        if t.size:
            th = np.asarray(h["theta"])[:, k, :]
            names_t = snap["theta_names"]
            if made["names"] != names_t:
                made["names"] = names_t
                for i, n in enumerate(names_t):
                    coef.line("t", n, source=theta, legend_label=n,
                              color=_COLORS[i % len(_COLORS)], line_width=1.5)
                legend = coef.legend[0]
                legend.label_text_font_size = "8pt"
                legend.spacing = 0
                legend.ncols = 2
                coef.add_layout(legend, "right")
            theta.data = {"t": t.tolist(), **{n: th[:, i].tolist()
                                              for i, n in enumerate(names_t)}}
            hist.data = dict(t=t.tolist(),
                             tracking=np.asarray(h["tracking"])[:, k].tolist(),
                             frf=np.asarray(h["figures"])[:, k, 0].tolist())

    doc.add_root(column(status, row(pick), row(mag, ph), row(coef, err), row(frf, log)))
    doc.add_periodic_callback(update, 500)


def _serve(host: str, port: int, token: str | None, snapshots, ready) -> None:
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
