"""The datagram format: round trips, and everything else refused."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ehss.errors import ParameterError
from ehss.live.layout import HEADER, HEADER_BYTES, MAGIC, RecordLayout, parse_fields


def test_channels_pair_ref_and_fb_by_suffix():
    lay = RecordLayout(("t", "ref1", "fb1", "ref2", "temp", "fb2"))
    assert lay.channels == ("1", "2")
    assert lay.ref_index == (1, 3) and lay.fb_index == (2, 5)
    assert lay.time_index == 0


@pytest.mark.parametrize("text", ["t,ref1", "t,fb1", "t,x", "t,ref1,fb1,ref1", "t,ref 1,fb1",
                                  ""])
def test_bad_field_lists_are_refused(text):
    with pytest.raises(ParameterError):
        parse_fields(text)


@settings(max_examples=50, deadline=None)
@given(n=st.integers(1, 50), first=st.integers(0, 2**63 - 1), seed=st.integers(0, 2**32 - 1))
def test_encode_decode_round_trip(n, first, seed):
    lay = RecordLayout(("t", "ref1", "fb1"))
    x = np.random.default_rng(seed).standard_normal((n, 3))
    data = lay.encode(first, x)
    assert len(data) == HEADER_BYTES + 24 * n
    got_first, got = lay.decode(data)
    assert got_first == first
    np.testing.assert_array_equal(got, x)  # bit-exact: float64 on the wire


def test_header_is_little_endian_as_documented():
    lay = RecordLayout(("ref1", "fb1"))
    data = lay.encode(258, np.array([[1.0, -2.0]]))
    assert data[:4] == b"EHSS"
    assert data[4:6] == b"\x01\x00"            # version 1
    assert data[6:8] == b"\x02\x00"            # two fields
    assert data[8:16] == (258).to_bytes(8, "little")
    assert np.frombuffer(data[16:], "<f8").tolist() == [1.0, -2.0]


def test_everything_else_decodes_to_none():
    lay = RecordLayout(("t", "ref1", "fb1"))
    good = lay.encode(0, np.ones((2, 3)))
    bad = [
        b"",
        good[:10],                                   # shorter than a header
        good[:-1],                                   # truncated sample
        good + b"\0" * 8,                            # not a whole sample
        b"XXXX" + good[4:],                          # foreign magic
        HEADER.pack(MAGIC, 2, 3, 0) + good[16:],     # unknown version
        HEADER.pack(MAGIC, 1, 4, 0) + good[16:],     # other field count
        good[:16] + np.array([np.nan] * 6).tobytes(),  # NaN values
        HEADER.pack(MAGIC, 1, 3, 0),                 # no samples
    ]
    for data in bad:
        assert lay.decode(data) is None
