"""The compensator datagram: round trips, every corruption refused, nothing raises."""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ehss.target import (
    FAULTS,
    MAX_PREVIEW,
    MAX_TAPS,
    RESULTS,
    Compensator,
    CompensatorFilter,
    CompensatorUpdate,
    Inbox,
    decode,
    encode,
)
from ehss.target import datagram as dg

from .cases import corrupted, frame
from .naive import random_compensator

DOCS = Path(__file__).resolve().parents[2] / "docs" / "target.md"


def _update(c: Compensator, **kw) -> CompensatorUpdate:
    args = {"channel": 2, "sequence": 10, "apply_index": 1000, "crossfade": 200} | kw
    return CompensatorUpdate(compensator=c, **args)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n_sections=st.integers(0, 16),
       n_taps=st.integers(1, MAX_TAPS), preview=st.integers(0, MAX_PREVIEW),
       channel=st.integers(0, 2**16 - 1), sequence=st.integers(0, 2**64 - 1),
       apply_index=st.integers(0, 2**64 - 1), crossfade=st.integers(0, 2**32 - 1))
def test_round_trip(seed, n_sections, n_taps, preview, channel, sequence, apply_index,
                    crossfade):
    c = random_compensator(np.random.default_rng(seed), n_sections, n_taps,
                           preview=preview, fs_hz=1234.5)
    u = _update(c, channel=channel, sequence=sequence, apply_index=apply_index,
                crossfade=crossfade)
    data = encode(u)
    assert len(data) == 52 + 48 * n_sections + 8 * n_taps
    assert decode(data) == u   # float64 on the wire: every coefficient exact


def test_the_encoder_writes_the_documented_layout():
    c = Compensator(sos=[[1.0, 0.5, 0.0, 1.0, -0.5, 0.25]], taps=[1.0, 0.5], preview=0,
                    fs_hz=5000.0)
    u = _update(c, channel=1, sequence=1, apply_index=100, crossfade=50)
    assert encode(u) == frame()


@pytest.mark.parametrize("what, data, fault", corrupted(), ids=[c[0] for c in corrupted()])
def test_every_corruption_is_its_fault(what, data, fault):
    assert decode(data) == fault


def test_fault_kinds_are_the_results_of_the_c_code_in_order():
    assert RESULTS[1:len(FAULTS) + 1] == FAULTS
    assert {f for _, _, f in corrupted()} == set(FAULTS)   # every kind is tested


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=3000))
def test_random_bytes_never_raise(data):
    got = decode(data)
    assert got in FAULTS or isinstance(got, CompensatorUpdate)


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=600), st.integers(0, 4), st.integers(0, 40))
def test_random_frames_with_a_valid_checksum_never_raise(payload, n_sections, n_taps):
    # past the frame checks: random header fields and coefficients, a correct checksum
    body = (b"EHSC" + struct.pack("<H", 1) + payload[:34].ljust(34, b"\0")
            + struct.pack("<I", n_sections) + payload[34:34 + 48 * n_sections]
            .ljust(48 * n_sections, b"\0") + struct.pack("<I", n_taps)
            + payload[:8 * n_taps].ljust(8 * n_taps, b"\1"))
    got = decode(body + struct.pack("<I", zlib.crc32(body)))
    assert got in FAULTS or isinstance(got, CompensatorUpdate)


@settings(max_examples=200, deadline=None)
@given(st.data())
def test_any_changed_byte_is_refused(data):
    good = frame(sos=np.tile([1.0, 0.3, 0.1, 1.0, -0.4, 0.2], (3, 1)), taps=np.ones(9))
    i = data.draw(st.integers(0, len(good) - 1))
    b = data.draw(st.integers(1, 255))
    bad = bytearray(good)
    bad[i] ^= b
    # CRC-32 detects every error confined to 32 consecutive bits, and the fields before
    # it are checked first: never accepted
    assert decode(bytes(bad)) in FAULTS


def _filters():
    return {1: CompensatorFilter(Compensator.delay(0, fs_hz=5000.0))}


def test_inbox_loads_updates_and_counts_every_refusal():
    inbox = Inbox(_filters())
    assert inbox.accept(frame(sequence=5)) == "ok"
    assert inbox.accept(frame(sequence=5)) == "stale"          # repeated
    assert inbox.accept(frame(sequence=4)) == "stale"          # late
    assert inbox.accept(frame(sequence=6, channel=7)) == "other_channel"
    assert inbox.accept(frame(sequence=6, preview=3)) == "other_preview"
    assert inbox.accept(frame(sequence=6, fs_hz=1000.0)) == "other_sample_rate"
    assert inbox.accept(frame(sequence=6)) == "busy"   # the first has not been taken up
    assert inbox.accept(b"\x00" * 10) == "truncated"
    assert inbox.last_sequence(1) == 5
    assert inbox.counters["ok"] == 1 and inbox.counters["stale"] == 2
    assert sum(inbox.counters.values()) == 8


def test_an_update_refused_as_busy_is_taken_when_sent_again():
    filters = _filters()
    inbox = Inbox(filters)
    assert inbox.accept(frame(sequence=1, apply_index=0, crossfade=10)) == "ok"
    filters[1].process(np.zeros(3))                    # taken up; fading until 10
    assert inbox.accept(frame(sequence=2, apply_index=0, crossfade=10)) == "ok"  # waits
    assert inbox.accept(frame(sequence=3)) == "busy"
    filters[1].process(np.zeros(10))                   # the fade ends, 2 is taken up
    assert inbox.accept(frame(sequence=3)) == "ok"
    assert filters[1].counters["loads"] == 2


def test_docs_show_the_module_table():
    # the format table of docs/target.md is the module's, line for line
    doc = DOCS.read_text(encoding="utf-8")
    table = [line for line in dg.__doc__.splitlines() if line.startswith(("====", "0 ",
                                                                          "4 ", "44 "))]
    assert table and all(line in doc for line in table)
