"""Hostile input on the newest commands: outputs onto an input's sidecar, live recordings
that are malformed, cut short or empty, UDP destinations that are no machine, a wild
datagram index, and standard streams that cannot take what a command prints.

Each case checks the promise made to users: exit 2 (1 where the fault is the
environment's, not the input's) with exactly one line on stderr, no traceback, and
every file of the folder byte-identical afterwards.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

import ehss
from ehss.cli import main
from ehss.io import write_table
from ehss.live import RecordLayout, UdpSource

SRC = str(Path(__file__).resolve().parents[2] / "src")


def _env(**extra: str) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = SRC + os.pathsep + env.get("PYTHONPATH", "")
    env.update(extra)
    return env


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()}


def _one_line(err: str, *words: str) -> None:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert "Traceback" not in err
    for w in words:
        assert w in lines[0], (w, lines[0])


@pytest.fixture(scope="module")
def simulated(tmp_path_factory) -> Path:
    """A record and its sidecar as ``ehss simulate`` writes them."""
    folder = tmp_path_factory.mktemp("sim")
    ref = ehss.signals.band_limited_random(band_hz=(2, 20), rms=1e-4, duration_s=3.0,
                                           fs=1000.0, seed=3)
    run = ehss.simulate("position", ref, seed=3)
    write_table(folder / "sim.csv", {"t": run.t, "reference": run.reference,
                                             "output": run.output},
                        metadata={"units": {"t": "s"}, "seed": 3})
    assert (folder / "sim.json").exists()
    return folder


@pytest.mark.parametrize("argv", [
    ["identify", "sim.csv", "--input", "reference", "--output", "output", "--na", "2",
     "--nb", "2", "--nc", "1", "--out", "sim.json"],
    ["identify", "sim.csv", "--input", "reference", "--output", "output", "--na", "2",
     "--nb", "2", "--nc", "1", "--out", "model.json", "--plot", "sim.json"],
    ["frf", "sim.csv", "--input", "reference", "--output", "output", "--out", "f.csv",
     "--plot", "sim.json"],
])
def test_an_output_never_replaces_an_inputs_sidecar(simulated, tmp_path, monkeypatch,
                                                    capsys, argv):
    for name in ("sim.csv", "sim.json"):
        (tmp_path / name).write_bytes((simulated / name).read_bytes())
    monkeypatch.chdir(tmp_path)
    before = _snapshot(tmp_path)
    assert main(argv) == 2
    _one_line(capsys.readouterr().err, "sim.json", "sidecar of the input 'sim.csv'")
    assert _snapshot(tmp_path) == before


@pytest.mark.parametrize("to", ["255.255.255.255:5005", "0.0.0.0:5005", "127.0.0.1:0"])
def test_stream_refuses_a_destination_that_is_no_machine(capsys, to):
    assert main(["stream", "--to", to, "--rig", "position", "--duration", "1"]) == 2
    _one_line(capsys.readouterr().err, repr(to))


def test_live_on_a_busy_port_names_the_port_not_the_allow_list(capsys):
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as busy:
        busy.bind(("127.0.0.1", 0))
        port = busy.getsockname()[1]
        code = main(["live", "--udp", f"127.0.0.1:{port}", "--fields", "t,ref1,fb1",
                     "--fs", "1000", "--quiet"])
    assert code == 2
    err = capsys.readouterr().err
    _one_line(err, f"cannot listen on 127.0.0.1:{port}")
    assert "--allow" not in err


# ------------------------------------------------------------------- live recordings
@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("rec") / "good.h5"
    assert main(["live", "--rig", "position", "--duration", "2", "--speed", "inf",
                 "--seed", "2", "--record", str(path), "--quiet"]) == 0
    return path


def _fields_not_json(h):
    h.attrs["fields"] = "t ref1 fb1"


def _fields_not_names(h):
    h.attrs["fields"] = json.dumps([1, 2, 3])


def _string_samples(h):
    n = h["samples"].shape[0]
    del h["samples"]
    h.create_dataset("samples", data=np.array([[b"x"] * 3] * n))


def _no_samples(h):
    h["samples"].resize((0, h["samples"].shape[1]))


def _bad_rate(h):
    h.attrs["fs"] = 0.0


@pytest.mark.parametrize(("edit", "words"), [
    (_fields_not_json, ("'fields' attribute",)),
    (_fields_not_names, ("'fields' attribute",)),
    (_string_samples, ("not numbers",)),
    (_no_samples, ("no samples",)),
    (_bad_rate, ("'fs'",)),
])
def test_live_replay_of_a_malformed_recording(recording, tmp_path, capsys, edit, words):
    path = tmp_path / "rec.h5"
    path.write_bytes(recording.read_bytes())
    with h5py.File(path, "a") as h:
        edit(h)
    before = _snapshot(tmp_path)
    assert main(["live", "--replay", str(path), "--speed", "inf", "--quiet"]) == 2
    _one_line(capsys.readouterr().err, "rec.h5", *words)
    assert _snapshot(tmp_path) == before


def test_live_replay_of_a_recording_cut_short_on_disk(recording, tmp_path, capsys):
    # opened for SWMR reading, HDF5 reads the chunks past the cut as zeros: a
    # "successful" replay of silence; the file's stored length tells it was cut
    path = tmp_path / "cut.h5"
    data = recording.read_bytes()
    path.write_bytes(data[: len(data) // 3])
    assert main(["live", "--replay", str(path), "--speed", "inf", "--quiet"]) == 2
    _one_line(capsys.readouterr().err, "cut.h5", "truncated")


def test_live_replays_a_record_written_by_simulate(simulated, capsys):
    # ehss simulate names its columns reference/output, not ref1/fb1
    assert main(["live", "--replay", str(simulated / "sim.csv"), "--speed", "inf",
                 "--quiet"]) == 0
    assert "3000 samples per channel" in capsys.readouterr().err


def test_live_replay_names_the_columns_it_needs(tmp_path, capsys):
    path = tmp_path / "r.csv"
    path.write_text("time,u,y\n" + "".join(f"{k / 100},{np.sin(k)},{np.cos(k)}\n"
                                            for k in range(300)))
    assert main(["live", "--replay", str(path), "--quiet"]) == 2
    _one_line(capsys.readouterr().err, "r.csv", "no ref<k>/fb<k> columns", "--fields")


# ------------------------------------------------------------------------- datagrams
def _received(src: UdpSource, datagrams: list[bytes]) -> list:
    """The blocks ``src`` makes of ``datagrams`` sent to it over loopback, 1 ms apart."""
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
            for datagram in datagrams:
                tx.sendto(datagram, src.address)
                time.sleep(0.001)
            blocks = []
            for _ in range(50):
                blocks += src.poll(0.02)
    finally:
        src.close()
    return blocks


def test_one_datagram_with_a_wild_index_is_dropped_not_believed():
    lay = RecordLayout(("t", "ref1", "fb1"))
    src = UdpSource(lay, ("127.0.0.1", 0), fs=1000.0)
    x = np.arange(60.0).reshape(20, 3)
    datagrams = [lay.encode(k, x[k:k + 1]) for k in range(20)]
    # well formed, but its index is the largest a uint64 holds
    datagrams.insert(10, lay.encode(2**64 - 1, x[10:11]))
    blocks = _received(src, datagrams)
    assert [b.first_index for b in blocks] == list(range(20))
    c = src.counters
    assert (c["malformed"], c["late"], c["lost_samples"], c["samples"]) == (1, 0, 0, 20)


def test_a_sender_that_restarts_its_count_is_followed():
    lay = RecordLayout(("t", "ref1", "fb1"))
    src = UdpSource(lay, ("127.0.0.1", 0), fs=1000.0)
    x = np.arange(30.0).reshape(10, 3)
    restart = 2**40  # far from the count: the first such datagram alone is not believed
    blocks = _received(src, [lay.encode(k if k < 5 else restart + k, x[k:k + 1])
                             for k in range(10)])
    assert [b.first_index for b in blocks] == [0, 1, 2, 3, 4] + [restart + k
                                                                 for k in range(6, 10)]
    assert src.counters["late"] == 0


# ----------------------------------------------------------------- standard streams
def _frf_cmd(simulated: Path, out: Path) -> list[str]:
    return [sys.executable, "-m", "ehss", "frf", str(simulated / "sim.csv"), "--input",
            "reference", "--output", "output", "--out", str(out)]


def test_stdout_a_closed_pipe(simulated, tmp_path):
    proc = subprocess.Popen(_frf_cmd(simulated, tmp_path / "f.csv"), env=_env(),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()  # as `ehss frf ... | true` leaves it
    with proc.stderr:
        err = proc.stderr.read().decode()
    assert proc.wait(120) == 1
    _one_line(err, "standard output")


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="no /dev/full on this system")
def test_stdout_a_full_device(simulated, tmp_path):
    with open("/dev/full", "w") as full:
        proc = subprocess.run(_frf_cmd(simulated, tmp_path / "f.csv"), env=_env(),
                              stdout=full, stderr=subprocess.PIPE, timeout=120)
    assert proc.returncode == 1
    _one_line(proc.stderr.decode(), "standard output", "No space left")


def test_a_latin1_terminal_reads_the_messages(simulated, tmp_path):
    proc = subprocess.run(_frf_cmd(simulated, tmp_path / "f.csv"),
                          env=_env(PYTHONIOENCODING="latin-1"), capture_output=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr.decode("latin-1")
    assert b"Traceback" not in proc.stderr
    assert (tmp_path / "f.csv").exists()


def test_an_unopenable_input_is_one_line(tmp_path, monkeypatch, capsys):
    # root reads any file whatever its mode, so the refusal is made by the loader
    import scipy.io

    path = tmp_path / "r.mat"
    scipy.io.savemat(path, {"u": np.sin(np.arange(500.0)), "y": np.cos(np.arange(500.0))})

    def refuse(name, *args, **kwargs):
        raise PermissionError(13, "Permission denied", str(name))

    monkeypatch.setattr(scipy.io, "loadmat", refuse)
    assert main(["frf", str(path), "--input", "u", "--output", "y", "--fs", "10", "--out",
                 str(tmp_path / "f.csv")]) == 2
    _one_line(capsys.readouterr().err, "r.mat", "Permission denied")


# ------------------------------------------------------------------------- records
@pytest.mark.parametrize(("values", "kind"), [
    (lambda u: [f"{x:.6f}" for x in u], "String"),
    (lambda u: u > 0, "Boolean"),
])
def test_a_parquet_column_of_text_or_booleans_is_named_as_such(tmp_path, capsys, values,
                                                               kind):
    import polars as pl

    u = np.sin(np.arange(400.0) / 7)
    path = tmp_path / "r.parquet"
    pl.DataFrame({"t": np.arange(400.0) / 100, "u": values(u), "y": np.cos(u)}).write_parquet(
        path)
    assert main(["frf", str(path), "--input", "u", "--output", "y", "--out",
                 str(tmp_path / "f.csv")]) == 2
    _one_line(capsys.readouterr().err, "r.parquet", "'u'", kind, "not numbers")


@pytest.mark.parametrize("suffix", [".mat", ".npz"])
def test_a_stored_sample_time_of_zero_is_named(tmp_path, capsys, suffix):
    import scipy.io

    u, y = np.sin(np.arange(400.0) / 7), np.cos(np.arange(400.0) / 5)
    path = tmp_path / f"r{suffix}"
    if suffix == ".mat":
        scipy.io.savemat(path, {"u": u, "y": y, "Ts": 0.0})
    else:
        np.savez(path, u=u, y=y, Ts=0.0)
    out = str(tmp_path / "f.csv")
    assert main(["frf", str(path), "--input", "u", "--output", "y", "--out", out]) == 2
    _one_line(capsys.readouterr().err, path.name, "'Ts' = 0 s", "--fs")
    # with the rate given, the stored zero is not in the way
    assert main(["frf", str(path), "--input", "u", "--output", "y", "--fs", "100",
                 "--out", out]) == 0


@pytest.mark.skipif(sys.platform == "darwin", reason="macOS file names are always UTF-8")
def test_a_file_name_that_is_not_utf8_in_a_plot_title(tmp_path, capsys):
    u, y = np.sin(np.arange(600.0) / 7), np.cos(np.arange(600.0) / 5)
    name = os.fsdecode(b"r\xff.csv")  # the byte 0xff is kept as a surrogate
    rows = "".join(f"{a},{b}\n" for a, b in zip(u, y, strict=True))
    (tmp_path / name).write_text("u,y\n" + rows)
    assert main(["frf", str(tmp_path / name), "--input", "u", "--output", "y", "--fs",
                 "100", "--out", str(tmp_path / "f.csv"), "--plot",
                 str(tmp_path / "f.png")]) == 0
    assert (tmp_path / "f.png").stat().st_size > 0


@pytest.mark.parametrize(("extra", "words"), [
    (["--u-scale", "0"], ("u_scale=0.0", "(0, inf)")),
    (["--y-scale", "-1"], ("y_scale=-1.0", "(0, inf)")),
    (["--memory", "1e-9"], ("memory_s=1e-09 s", "one sample at 1000 Hz")),
    (["--band", "10", "900"], ("upper edge 900 Hz", "fs/2 = 500 Hz")),
])
def test_live_settings_that_mean_nothing_are_refused(tmp_path, capsys, extra, words):
    report = tmp_path / "r.json"
    assert main(["live", "--rig", "position", "--duration", "1", "--speed", "inf",
                 "--quiet", "--report", str(report), *extra]) == 2
    err = [ln for ln in capsys.readouterr().err.splitlines() if "error" in ln]
    assert len(err) == 1 and all(w in err[0] for w in words), err
    assert not report.exists()


@pytest.mark.parametrize(("argv", "word"), [
    (["live", "--rig", "position", "--duration", "2", "--learn", "1e30"], "--learn"),
    (["live", "--rig", "position", "--duration", "2", "--compare", "recent",
      "--recent", "1e30"], "--recent"),
    (["live", "--rig", "position", "--duration", "2", "--update", "inf"], "--update"),
    (["stream", "--rig", "position", "--duration", "1e30", "--to", "127.0.0.1:9"],
     "duration_s=1e+30"),
])
def test_a_time_too_long_for_memory_or_not_finite_is_refused(argv, word, capsys):
    # a learning time or a record of 1e30 s would be an array of 1e33 samples, an
    # evaluation every inf seconds a count that does not exist: one line, exit 2
    assert main([*argv, "--speed", "inf"] if argv[0] == "live" else argv) == 2
    _one_line(capsys.readouterr().err, word)
