"""Hostile input to ``ehss stream``, run as users run it (``python -m ehss stream``): a
destination that is no machine, rates and sizes that mean nothing, a missing or garbled
file. Each is one line on stderr and exit 2 before a datagram is sent; no file changes.
"""

from __future__ import annotations

import numpy as np
import pytest

from ehss.io import write_table

RIG = ["stream", "--rig", "position", "--duration", "0.5", "--speed", "inf"]
TO = ["--to", "127.0.0.1:5999"]

DESTINATIONS = {
    "no port": "127.0.0.1",
    "port zero": "127.0.0.1:0",
    "port text": "127.0.0.1:udp",
    "port out of range": "127.0.0.1:65536",
    "broadcast": "255.255.255.255:5005",
    "any address": "0.0.0.0:5005",
    "unknown host": "no-such-host.invalid:5005",
    "empty": "",
}


@pytest.mark.parametrize("case", list(DESTINATIONS))
def test_a_destination_that_is_no_machine(tmp_path, refused, case):
    to = DESTINATIONS[case]
    refused([*RIG, "--to", to], tmp_path, repr(to))


SETTINGS = {
    "rate zero": (["--fs", "0"], ("fs",)),
    "rate negative": (["--fs", "-1000"], ("fs",)),
    "rate nan": (["--fs", "nan"], ("fs",)),
    "rate infinite": (["--fs", "inf"], ("fs",)),
    "rate text": (["--fs", "fast"], ("--fs",)),
    "channels zero": (["--channels", "0"], ("channels",)),
    "channels huge": (["--channels", "100000"], ("channels",)),
    "channels negative": (["--channels", "-1"], ("channels",)),
    "packet of no samples": (["--samples-per-packet", "0"], ("samples",)),
    "packet beyond a datagram": (["--samples-per-packet", "100000"], ("65507 bytes",)),
    "duration zero": (["--duration", "0"], ("duration",)),
    "duration negative": (["--duration", "-2"], ("duration",)),
    "speed zero": (["--speed", "0"], ("speed",)),
    "speed nan": (["--speed", "nan"], ("speed",)),
    "event after the run": (["--event", "9:mass_kg=350"], ("--event",)),
    "event garbled": (["--event", "mass"], ("mass",)),
    "params missing": (["--params", "none.toml"], ("none.toml",)),
}


@pytest.mark.parametrize("case", list(SETTINGS))
def test_settings_that_mean_nothing(tmp_path, refused, case):
    extra, words = SETTINGS[case]
    refused([*RIG, *TO, *extra], tmp_path, *words)


def _good(path):
    t = np.arange(500) / 500.0
    write_table(path, {"t": t, "ref1": np.sin(20 * t), "fb1": np.cos(20 * t)}, metadata={})


FILES = {
    "missing": (None, ("none.csv",)),
    "empty": (b"", ("r.csv",)),
    "garbled": (bytes(range(256)) * 4, ("r.csv",)),
    "header only": (b"t,ref1,fb1\n", ("r.csv",)),
    "text in a column": (b"t,ref1,fb1\n0,1,2\n0.002,x,3\n0.004,1,2\n", ("r.csv",)),
    "nan": (b"t,ref1,fb1\n0,1,2\n0.002,nan,3\n0.004,1,2\n", ("r.csv", "nan", "data row 2")),
}


@pytest.mark.parametrize("case", list(FILES))
def test_a_missing_or_garbled_file(tmp_path, refused, case):
    content, words = FILES[case]
    name = "none.csv" if content is None else "r.csv"
    if content is not None:
        (tmp_path / name).write_bytes(content)
    refused(["stream", "--replay", name, "--speed", "inf", *TO], tmp_path, *words)


@pytest.mark.parametrize(("extra", "words"), [
    (["--fields", "t,ref1,fb7"], ("fb1",)),
    (["--fields", ""], ("--fields",)),
    (["--duration", "1"], ("--duration",)),
    (["--event", "0.1:mass_kg=350"], ("--event",)),
    (["--fs", "0"], ("fs",)),
])
def test_replay_settings_that_mean_nothing(tmp_path, refused, extra, words):
    _good(tmp_path / "r.csv")
    refused(["stream", "--replay", "r.csv", "--speed", "inf", *TO, *extra], tmp_path, *words)
