"""Recording of a live session to HDF5, appended while it runs.

The file is written in HDF5's single-writer/multiple-reader mode (SWMR): every flush
leaves it consistent, so it can be read while the session runs and stays readable when
the process is killed (everything up to the last flush, at most ``flush_s`` old). The
writing is done by a thread of its own (HDF5 releases the interpreter while it writes):
the processing only hands arrays over, and never waits for the disk.

Layout:

``/samples``           (n, F) float64, the samples as received, fields in layout order
``/sample_index``      (n,) int64, stream index of each row (a jump is a gap)
``/estimates/t``       (m,) float64, stream time of each evaluation, s
``/estimates/theta``   (m, C, P) float64, θ̂ = [a1..a_na, b0..b_nb, c1..c_nc] per channel
``/estimates/figures`` (m, C, 4) float64, frf_db, gain_db, pole_shift, test (NaN: not yet)
``/events``            (k,) JSON strings: alarms, clears, messages, start and stop
``/counters``          (j, len(COUNTERS)) int64, the source's counters at each flush

The root attributes hold the fields, channels, sample rate, the settings and the
versions (JSON in ``settings``).
"""

from __future__ import annotations

import json
import queue
import threading
import time
from pathlib import Path

import h5py
import numpy as np

from ehss._files import check_writable
from ehss._provenance import versions
from ehss.errors import DataError, EhssError
from ehss.live.detect import FIGURES
from ehss.live.layout import RecordLayout
from ehss.live.source import COUNTERS

__all__ = ["LiveRecorder", "check_new_recording", "read_recording"]


def check_new_recording(path: str | Path) -> Path:
    """The one rule of recordings: ``path`` can be written (:func:`ehss._files.check_writable`)
    and does not exist, for a recording is never overwritten.

    Raises
    ------
    DataError
        If ``path`` exists, or cannot be written.
    """
    path = check_writable(path)
    if path.exists() or path.is_symlink():
        raise DataError(f"{str(path)!r} exists: a recording is never overwritten")
    return path


class LiveRecorder:
    """Append samples, estimates, events and counters to an HDF5 file.

    Parameters
    ----------
    path : str or Path
        The file; it must not exist (a recording is never overwritten).
    layout : RecordLayout
    fs : float
    n_params : int
        Length of θ̂.
    settings : dict
        JSON-able settings stored with the file.
    flush_s : float
        Longest time between flushes to disk.
    """

    def __init__(self, path: str | Path, layout: RecordLayout, fs: float, n_params: int,
                 settings: dict, *, flush_s: float = 1.0) -> None:
        path = check_new_recording(path)
        self.path = path
        self.layout = layout
        self._flush_s = flush_s
        c, f = len(layout.channels), layout.n_fields
        rows = max(256, int(fs * 0.25))
        try:
            self._file = h5py.File(path, "w-", libver="latest")
        except OSError as exc:
            raise DataError(f"cannot create {str(path)!r}: {exc}") from None
        h = self._file
        h.attrs["fields"] = json.dumps(list(layout.fields))
        h.attrs["channels"] = json.dumps(list(layout.channels))
        h.attrs["fs"] = float(fs)
        h.attrs["figures"] = json.dumps(list(FIGURES))
        h.attrs["counters"] = json.dumps(list(COUNTERS))
        h.attrs["settings"] = json.dumps(settings)
        h.attrs["versions"] = json.dumps(versions())
        self._samples = h.create_dataset("samples", (0, f), maxshape=(None, f),
                                         chunks=(rows, f), dtype="f8")
        self._index = h.create_dataset("sample_index", (0,), maxshape=(None,),
                                       chunks=(rows,), dtype="i8")
        g = h.create_group("estimates")
        self._t = g.create_dataset("t", (0,), maxshape=(None,), chunks=(256,), dtype="f8")
        self._theta = g.create_dataset("theta", (0, c, n_params),
                                       maxshape=(None, c, n_params),
                                       chunks=(64, c, n_params), dtype="f8")
        self._fig = g.create_dataset("figures", (0, c, len(FIGURES)),
                                     maxshape=(None, c, len(FIGURES)),
                                     chunks=(64, c, len(FIGURES)), dtype="f8")
        self._events = h.create_dataset("events", (0,), maxshape=(None,), chunks=(64,),
                                        dtype=h5py.string_dtype())
        self._counters = h.create_dataset("counters", (0, len(COUNTERS)),
                                          maxshape=(None, len(COUNTERS)),
                                          chunks=(64, len(COUNTERS)), dtype="i8")
        h.swmr_mode = True
        self._inbox: queue.SimpleQueue = queue.SimpleQueue()
        self.error: BaseException | None = None
        self._writer = threading.Thread(target=self._write_loop, name="ehss-recorder",
                                        daemon=True)
        self._pend_s: list[np.ndarray] = []
        self._pend_i: list[tuple[int, int]] = []
        self._pend_t: list[float] = []
        self._pend_theta: list[np.ndarray] = []
        self._pend_fig: list[np.ndarray] = []
        self._pend_ev: list[str] = []
        self._last = time.monotonic()
        self.rows = 0
        self.closed = False
        self._writer.start()

    # ------------------------------------------------------------------ the caller's side
    # the caller fills these lists; each flush hands them to the writer in one piece
    def samples(self, first_index: int, samples: np.ndarray) -> None:
        """Append consecutive samples starting at stream index ``first_index``."""
        self._pend_s.append(samples)
        self._pend_i.append((first_index, samples.shape[0]))

    def estimate(self, t_s: float, theta: np.ndarray, figures: np.ndarray) -> None:
        """Append one evaluation: θ̂ (C, P) and figures (C, 3) at stream time ``t_s``."""
        self._pend_t.append(t_s)
        self._pend_theta.append(theta)
        self._pend_fig.append(figures)

    def event(self, record: dict) -> None:
        """Append one event (a JSON-able dict)."""
        self._pend_ev.append(json.dumps(record, allow_nan=True))

    def _hand_over(self, kind: str, counters: dict[str, int]) -> None:
        batch = (self._pend_s, self._pend_i, self._pend_t, self._pend_theta, self._pend_fig,
                 self._pend_ev)
        self._pend_s, self._pend_i, self._pend_t = [], [], []
        self._pend_theta, self._pend_fig, self._pend_ev = [], [], []
        self._inbox.put((kind, batch, dict(counters)))

    def maybe_flush(self, counters: dict[str, int]) -> None:
        """Ask for a flush when ``flush_s`` has passed since the last request.

        Raises
        ------
        DataError
            If writing failed (e.g. the disk is full): the session stops cleanly.
        """
        if self.error is not None:
            raise DataError(f"recording to {str(self.path)!r} failed: {self.error}")
        if time.monotonic() - self._last >= self._flush_s:
            self._last = time.monotonic()
            self._hand_over("flush", counters)

    def close(self, counters: dict[str, int]) -> None:
        """Write everything, flush and close; waits for the writer (idempotent)."""
        if not self.closed:
            self.closed = True
            self._hand_over("close", counters)
            self._writer.join()

    # ------------------------------------------------------------------ the writer thread
    def _write_loop(self) -> None:
        while True:
            kind, batch, counters = self._inbox.get()
            if self.error is None:
                try:
                    self._write(batch, counters)
                except (OSError, ValueError, EhssError) as exc:   # disk full, file gone
                    self.error = exc
            if kind == "close":
                try:
                    self._file.close()
                except (OSError, ValueError) as exc:
                    self.error = self.error or exc
                return

    @staticmethod
    def _append(ds: h5py.Dataset, rows: np.ndarray) -> None:
        n = ds.shape[0]
        ds.resize(n + rows.shape[0], axis=0)
        ds[n:] = rows

    def _write(self, batch: tuple, counters: dict[str, int]) -> None:
        """Write one handed-over batch and make it durable for readers (writer thread)."""
        xs, idx, ts, thetas, figs, events = batch
        if xs:
            x = np.concatenate(xs)
            self._append(self._samples, x)
            self._append(self._index, np.concatenate([np.arange(f, f + n) for f, n in idx]))
            self.rows += x.shape[0]
        if ts:
            self._append(self._t, np.asarray(ts))
            self._append(self._theta, np.stack(thetas))
            self._append(self._fig, np.stack(figs))
        if events:
            self._append(self._events, np.array(events, dtype=object))
        self._append(self._counters, np.array([[counters[k] for k in COUNTERS]]))
        self._file.flush()


def read_recording(path: str | Path) -> dict:
    """A recording as plain arrays (works on a file still being written).

    Returns
    -------
    dict
        ``fields, channels, fs, settings, samples, sample_index, t, theta, figures,
        events`` (list of dicts), ``counters`` (dict of the last row).
    """
    path = Path(path)
    try:
        with h5py.File(path, "r", libver="latest", swmr=True) as h:
            names = json.loads(h.attrs["counters"])
            counters = h["counters"][-1] if h["counters"].shape[0] else np.zeros(len(names))
            return {
                "fields": json.loads(h.attrs["fields"]),
                "channels": json.loads(h.attrs["channels"]),
                "fs": float(h.attrs["fs"]),
                "settings": json.loads(h.attrs["settings"]),
                "versions": json.loads(h.attrs["versions"]),
                "samples": h["samples"][...],
                "sample_index": h["sample_index"][...],
                "t": h["estimates/t"][...],
                "theta": h["estimates/theta"][...],
                "figures": h["estimates/figures"][...],
                "events": [json.loads(e) for e in h["events"].asstr()[...]],
                "counters": dict(zip(names, (int(v) for v in counters), strict=True)),
            }
    except (OSError, KeyError) as exc:
        raise DataError(f"{str(path)!r} is not a readable ehss live recording: {exc}") \
            from None
