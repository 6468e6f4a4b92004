"""The C99 filter and decoder, compiled here with the system's C compiler through cffi,
against the Python ones."""

from __future__ import annotations

import importlib.util
import re
import shutil
import subprocess
from pathlib import Path

import cffi
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose

import ehss.target
from ehss.target import (
    MAX_PREVIEW,
    MAX_SECTIONS,
    MAX_TAPS,
    RESULTS,
    Compensator,
    CompensatorFilter,
    CompensatorUpdate,
    Inbox,
    decode,
    encode,
)
from ehss.target.datagram import MAX_DATAGRAM_BYTES

from .cases import corrupted, frame
from .naive import random_compensator

C_DIR = Path(ehss.target.__file__).with_name("c")
CC = shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")
pytestmark = pytest.mark.skipif(CC is None, reason="no C compiler (cc, gcc or clang) on "
                                "this machine to compile the target's C code")

_C_NAMES = ["EHSS_COMP_OK"] + [f"EHSS_COMP_FAULT_{r.upper()}" for r in RESULTS[1:13]] + [
    f"EHSS_COMP_{r.upper()}" for r in RESULTS[13:]]

CDEF = """
typedef struct {
    uint16_t channel; uint64_t sequence; double fs_hz; uint64_t apply_index;
    uint32_t crossfade; uint32_t preview; uint32_t n_sections; double sos[@SECTIONS@][6];
    uint32_t n_taps; double taps[@TAPS@];
} ehss_comp_update;
typedef struct {
    uint32_t loads; uint32_t swaps; uint32_t superseded; uint32_t late;
    uint32_t decoded[18];
} ehss_comp_counters;
typedef struct { uint64_t index; int has_next; ehss_comp_counters counters; ...; }
    ehss_comp_state;
#define EHSS_COMP_MAX_SECTIONS ...
#define EHSS_COMP_MAX_TAPS ...
#define EHSS_COMP_MAX_PREVIEW ...
#define EHSS_COMP_MAX_DATAGRAM_BYTES ...
#define EHSS_COMP_N_RESULTS ...
int ehss_comp_init(ehss_comp_state *s, uint16_t channel, uint32_t preview, double fs_hz,
                   uint64_t start_index);
int ehss_comp_parse(const unsigned char *buf, size_t len, ehss_comp_update *out);
long ehss_comp_datagram_channel(const unsigned char *buf, size_t len);
int ehss_comp_decode(ehss_comp_state *s, const unsigned char *buf, size_t len);
double ehss_comp_step(ehss_comp_state *s, double x);
uint64_t ehss_comp_settle_samples(uint32_t n_sections, const double (*sos)[6],
                                  uint32_t n_taps);
void run_block(ehss_comp_state *s, const double *x, double *y, size_t n);
""".replace("@SECTIONS@", str(MAX_SECTIONS)).replace("@TAPS@", str(MAX_TAPS)) + "".join(
    f"static const int {name};\n" for name in _C_NAMES)

RUN_BLOCK = """
void run_block(ehss_comp_state *s, const double *x, double *y, size_t n)
{
    size_t i;
    for (i = 0; i < n; ++i) y[i] = ehss_comp_step(s, x[i]);
}
"""


@pytest.fixture(scope="module")
def c(tmp_path_factory):
    """The compiled C code: ``(ffi, lib)``."""
    ffi = cffi.FFI()
    ffi.cdef(CDEF)
    ffi.set_source("_ehss_comp_under_test", '#include "ehss_compensator.h"\n' + RUN_BLOCK,
                   sources=[str(C_DIR / "ehss_compensator.c")], include_dirs=[str(C_DIR)],
                   # ISO C, and multiply and add kept apart as Python computes them
                   extra_compile_args=["-std=c99", "-O2", "-ffp-contract=off"],
                   libraries=["m"])
    path = ffi.compile(tmpdir=str(tmp_path_factory.mktemp("cffi")))
    spec = importlib.util.spec_from_file_location("_ehss_comp_under_test", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.ffi, module.lib


def test_the_c_code_compiles_as_strict_portable_c99(tmp_path):
    # a target short of memory may compile it with a smaller FIR
    for std_flags in (["-std=c99", "-O2"], ["-std=c99", "-O0"],
                      ["-std=c99", "-O2", "-DEHSS_COMP_MAX_TAPS=64"]):
        done = subprocess.run(
            [CC, *std_flags, "-Wall", "-Wextra", "-pedantic", "-Werror", "-c",
             str(C_DIR / "ehss_compensator.c"), "-o", str(tmp_path / "comp.o")],
            capture_output=True, text=True)
        assert done.returncode == 0, done.stderr


def test_the_c_code_includes_only_string_h_stdint_h_and_math_h():
    text = "".join((C_DIR / n).read_text() for n in ("ehss_compensator.h",
                                                    "ehss_compensator.c"))
    assert set(re.findall(r"#include\s*<([^>]+)>", text)) <= {"string.h", "stdint.h",
                                                              "stddef.h", "math.h"}
    assert "malloc" not in text and "[n]" not in text


def test_sizes_and_results_are_the_pythons(c):
    _, lib = c
    assert lib.EHSS_COMP_MAX_SECTIONS == MAX_SECTIONS
    assert lib.EHSS_COMP_MAX_TAPS == MAX_TAPS
    assert lib.EHSS_COMP_MAX_PREVIEW == MAX_PREVIEW
    assert lib.EHSS_COMP_MAX_DATAGRAM_BYTES == MAX_DATAGRAM_BYTES
    assert lib.EHSS_COMP_N_RESULTS == len(RESULTS)
    assert [getattr(lib, n) for n in _C_NAMES] == list(range(len(RESULTS)))


@pytest.mark.parametrize("what, data, fault", corrupted(), ids=[x[0] for x in corrupted()])
def test_the_c_parser_refuses_every_corruption_as_python_does(c, what, data, fault):
    ffi, lib = c
    out = ffi.new("ehss_comp_update *")
    # a copy of exactly len(data) bytes: reading one beyond would be a bug that
    # valgrind or ASan would show; here the results must match
    buf = ffi.new("unsigned char[]", max(len(data), 1))
    ffi.memmove(buf, data, len(data))
    assert RESULTS[lib.ehss_comp_parse(buf, len(data), out)] == fault


def test_the_c_parser_reads_what_python_writes(c, rng):
    ffi, lib = c
    for n_sections, n_taps in ((0, 1), (3, 20), (MAX_SECTIONS, MAX_TAPS)):
        comp = random_compensator(rng, n_sections, n_taps, preview=7, fs_hz=4321.0)
        u = CompensatorUpdate(channel=9, sequence=2**63 + 5, apply_index=2**40 + 3,
                              crossfade=70000, compensator=comp)
        data = encode(u)
        out = ffi.new("ehss_comp_update *")
        assert lib.ehss_comp_parse(data, len(data), out) == lib.EHSS_COMP_OK
        assert (out.channel, out.sequence, out.apply_index, out.crossfade, out.preview,
                out.fs_hz) == (9, 2**63 + 5, 2**40 + 3, 70000, 7, 4321.0)
        assert (out.n_sections, out.n_taps) == (n_sections, n_taps)
        sos = np.array([[out.sos[i][j] for j in range(6)] for i in range(n_sections)])
        taps = np.array([out.taps[j] for j in range(n_taps)])
        assert np.array_equal(sos.reshape(-1, 6), comp.sos)
        assert np.array_equal(taps, comp.taps)
        assert lib.ehss_comp_datagram_channel(data, len(data)) == 9
    assert lib.ehss_comp_datagram_channel(b"EHSC", 4) == -1


HARNESS = r"""
#include <stdio.h>
#include <stdlib.h>
#include "ehss_compensator.h"

/* Each record of the file: a uint32 length, then that many bytes. Each datagram is
 * copied into a heap block of exactly its length, so that a read beyond it is caught
 * by AddressSanitizer; prints the parse result of each. */
int main(int argc, char **argv)
{
    static ehss_comp_state s;
    static ehss_comp_update u;
    unsigned char head[4];
    FILE *f = argc > 1 ? fopen(argv[1], "rb") : NULL;
    if (f == NULL) return 3;
    ehss_comp_init(&s, 1, 0, 5000.0, 0);
    while (fread(head, 1, 4, f) == 4) {
        size_t n = (size_t)head[0] | (size_t)head[1] << 8 | (size_t)head[2] << 16
                   | (size_t)head[3] << 24;
        unsigned char *buf = malloc(n);
        if (n > 0 && (buf == NULL || fread(buf, 1, n, f) != n)) return 3;
        printf("%d\n", ehss_comp_parse(buf, n, &u));
        ehss_comp_datagram_channel(buf, n);
        ehss_comp_decode(&s, buf, n);
        ehss_comp_step(&s, 1.0);
        free(buf);
    }
    fclose(f);
    return 0;
}
"""


def test_the_c_parser_never_reads_beyond_the_datagram(tmp_path, rng):
    exe = tmp_path / "harness"
    (tmp_path / "harness.c").write_text(HARNESS)
    build = subprocess.run(
        [CC, "-std=c99", "-g", "-O1", "-fsanitize=address,undefined",
         "-fno-sanitize-recover=all", "-I", str(C_DIR), str(tmp_path / "harness.c"),
         str(C_DIR / "ehss_compensator.c"), "-o", str(exe), "-lm"], capture_output=True,
        text=True)
    if build.returncode != 0:
        pytest.skip(f"the C compiler cannot build with AddressSanitizer: {build.stderr}")
    big = encode(CompensatorUpdate(
        channel=1, sequence=1, apply_index=0, crossfade=0,
        compensator=random_compensator(rng, MAX_SECTIONS, MAX_TAPS)))
    cases = [big[:n] for n in range(len(big) + 1)]           # every truncation
    cases += [data for _, data, _ in corrupted()]
    cases += [rng.bytes(int(n)) for n in rng.integers(0, 3000, 200)]
    cases += [b"EHSC\x01\x00" + rng.bytes(int(n)) for n in rng.integers(0, 3000, 200)]
    with open(tmp_path / "cases.bin", "wb") as f:
        for data in cases:
            f.write(len(data).to_bytes(4, "little") + data)
    done = subprocess.run([str(exe), str(tmp_path / "cases.bin")], capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    got = [RESULTS[int(line)] for line in done.stdout.split()]
    expected = [decode(data) for data in cases]
    assert got == [e if isinstance(e, str) else "ok" for e in expected]


def _run_both(c, x, preview, events):
    """Drive the C state and the Python filter and inbox over ``x``; between blocks,
    hand each the datagrams ``events`` = [(sample, bytes)]. Returns both drives, the
    results of each datagram on each side, and both filters' counters."""
    ffi, lib = c
    state = ffi.new("ehss_comp_state *")
    assert lib.ehss_comp_init(state, 1, preview, 5000.0, 0) == lib.EHSS_COMP_OK
    f = CompensatorFilter(Compensator.delay(preview, fs_hz=5000.0))
    inbox = Inbox({1: f})
    y_py, y_c = np.empty_like(x), np.empty_like(x)
    results = []
    start = 0
    for at, data in [*events, (x.size, None)]:
        y_py[start:at] = f.process(x[start:at])
        lib.run_block(state, ffi.from_buffer("double[]", x[start:at]),
                      ffi.from_buffer("double[]", y_c[start:at]), at - start)
        start = at
        if data is not None:
            results.append((inbox.accept(data),
                            RESULTS[lib.ehss_comp_decode(state, data, len(data))]))
    counters_c = {k: getattr(state.counters, k) for k in ("loads", "swaps", "superseded",
                                                          "late")}
    counters_py = {k: f.counters[k] for k in counters_c}
    decoded = [state.counters.decoded[i] for i in range(len(RESULTS))]
    return y_py, y_c, results, (counters_py, counters_c), (inbox.counters, decoded)


def _scenario(rng, preview):
    """Updates that exercise every path: shadow, cross-fade, a load waiting for a fade
    to end, busy, superseded, late, an outright switch, stale, refused ones."""
    def upd(seq, k0, n, *, s=3, t=20, p=preview, channel=1, fs_hz=5000.0):
        comp = random_compensator(rng, s, t, preview=p, fs_hz=fs_hz)
        return encode(CompensatorUpdate(channel=channel, sequence=seq, apply_index=k0,
                                        crossfade=n, compensator=comp))
    wait_for_fade = upd(11, 0, 3000)
    return [
        (10_000, upd(1, 30_000, 5_000)),                      # shadow 20 000, fade
        (32_000, upd(2, 40_000, 100)),                        # during the fade: waits
        (33_000, upd(3, 40_000, 100)),                        # busy
        (40_000, upd(3, 200_000, 50_000)),                    # long shadow
        (100_000, upd(4, 150_000, 1, s=MAX_SECTIONS, t=MAX_TAPS)),  # supersedes it
        (120_000, upd(4, 0, 10)),                             # stale
        (130_000, frame(sequence=5, crc=1)),                  # checksum
        (140_000, upd(5, 0, 10, p=preview + 1)),              # other preview
        (150_500, upd(6, 0, 10, channel=2)),                  # other channel
        (150_600, upd(6, 0, 10, fs_hz=5006.0)),               # 0.12 % off: refused
        (150_700, upd(7, 0, 10, fs_hz=5004.0)),               # 0.08 % off: taken
        (300_000, upd(10, 250_000, 2_000)),                   # late: fades once settled
        (301_000, wait_for_fade),                             # waits, then late
        (301_500, frame(sos=[[1.0, 0, 0, 1, 0, 1.0]], sequence=12)),  # unstable
        (600_000, upd(20, 600_500, 0)),                       # switch outright
        (700_000, upd(21, 700_000, 100_000, s=MAX_SECTIONS, t=MAX_TAPS)),
        (900_000, upd(22, 950_000, 30_000, s=0, t=1)),
    ]


def test_c_filter_equals_python_over_a_million_samples_with_swaps(c):
    rng = np.random.default_rng(11)
    preview = 5
    x = rng.standard_normal(1_000_000)
    events = _scenario(rng, preview)
    y_py, y_c, results, counters, decoded = _run_both(c, x, preview, events)
    # the same operations in the same order on IEEE doubles, with the C compiled
    # without fused multiply-adds: expected equal to the last bit; 1e-12 of the drive's
    # scale leaves room for a compiler that fuses some (each fused operation differs by
    # under an ulp, and an error cannot grow through stable sections)
    assert_allclose(y_c, y_py, rtol=0, atol=1e-12 * np.max(np.abs(y_py)))
    assert [py for py, _ in results] == [cc for _, cc in results]
    assert [py for py, _ in results] == [
        "ok", "ok", "busy", "ok", "ok", "stale", "checksum", "other_preview",
        "other_channel", "other_sample_rate", "ok", "ok", "ok", "unstable", "ok", "ok",
        "ok"]
    assert counters[0] == counters[1]
    # late: the two loaded after their apply index, the one that waited for a fade, and
    # the one at 700 000 applying from the sample it came (no time to settle)
    assert counters[0] == {"loads": 10, "swaps": 9, "superseded": 1, "late": 4}
    assert list(decoded[0].values()) == decoded[1]


def test_the_c_state_starts_as_the_reference_delayed_by_the_preview(c):
    ffi, lib = c
    state = ffi.new("ehss_comp_state *")
    assert lib.ehss_comp_init(state, 0, MAX_PREVIEW + 1, 5000.0, 0) == \
        lib.EHSS_COMP_FAULT_PREVIEW
    for fs in (0.0, float("nan"), float("inf"), 2e9):
        assert lib.ehss_comp_init(state, 0, 2, fs, 0) == lib.EHSS_COMP_FAULT_SAMPLE_RATE
    assert lib.ehss_comp_init(state, 0, 2, 5000.0, 0) == lib.EHSS_COMP_OK
    assert [lib.ehss_comp_step(state, v) for v in (1.0, 2.0, 3.0, 4.0)] == [0, 0, 1, 2]


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1),
       loads=st.lists(st.tuples(st.integers(1, 400), st.integers(-200, 400),
                                st.integers(0, 300)), min_size=1, max_size=12))
def test_c_and_python_agree_on_any_schedule_of_loads(c, seed, loads):
    # loads (gap since the previous one, apply index relative to now, cross-fade): any
    # mix of shadow runs, late loads, loads during fades (waiting, busy), supersedings
    rng = np.random.default_rng(seed)
    x = rng.standard_normal(sum(g for g, _, _ in loads) + 500)
    events, at = [], 0
    for seq, (gap, ahead, n) in enumerate(loads, start=1):
        at += gap
        comp = random_compensator(rng, int(rng.integers(0, 4)), int(rng.integers(1, 30)))
        events.append((at, encode(CompensatorUpdate(
            channel=1, sequence=seq, apply_index=max(at + ahead, 0), crossfade=n,
            compensator=comp))))
    y_py, y_c, results, counters, decoded = _run_both(c, x, 0, events)
    # the same operations in the same order (tolerance: see the test above)
    assert_allclose(y_c, y_py, rtol=0, atol=1e-12 * max(1.0, np.max(np.abs(y_py))))
    assert [py for py, _ in results] == [cc for _, cc in results]
    assert counters[0] == counters[1]
    assert list(decoded[0].values()) == decoded[1]


def test_the_c_settling_time_is_the_pythons(c, rng):
    ffi, lib = c
    comps = [random_compensator(rng, n, int(rng.integers(1, MAX_TAPS + 1)))
             for n in (0, 1, 2, 7, MAX_SECTIONS) for _ in range(20)]
    comps += [Compensator(sos=[[1.0, 0, 0, 1.0, a1, a2]], taps=[1.0], preview=0,
                          fs_hz=5000.0)
              for a1, a2 in ((0.0, 0.0), (-0.5, 0.0), (-2 * 0.9999, 0.9999**2),
                             (0.0, 0.999999), (1.5, 0.5625), (-1e-300, 0.0))]
    for comp in comps:
        sos = ffi.new("double[][6]", max(comp.n_sections, 1))
        for i, row in enumerate(np.array(comp.sos)):
            for j, v in enumerate(row):
                sos[i][j] = v
        assert lib.ehss_comp_settle_samples(comp.n_sections, sos, comp.n_taps) == \
            comp.settle_samples
