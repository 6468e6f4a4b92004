"""The target filter in Python: real-time factor for 8 channels at 5 kHz.

``CompensatorFilter.process`` runs 8 channels (one filter each) over blocks of 5
samples (1 ms at 5 kHz, the block of the ``ehss live`` stream) and of 50 samples, for a
typical compensator (4 sections, 32 taps), the 0.256 s that ``ehss live`` designs at
5 kHz (16 sections, 1280 taps) and the largest the target holds (16 sections, 2048),
steady and with every channel in a cross-fade (two filters running). Real-time factor:
stream seconds processed per wall second (above 1: faster than real time). In the same
run, the same kernel interpreted by Python (``filter_block.py_func``) on a shorter
stretch gives the speed-up numba brings; and, when a C compiler and cffi are there,
the C code (one ``ehss_comp_step`` per sample, called from a C loop) gives the ratio
to the target's own code, and the time of one ``ehss_comp_decode`` of such a datagram.

Usage::

    python benchmarks/bench_target.py [--seconds 2]
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ehss.target import MAX_TAPS, CompensatorFilter  # noqa: E402
from ehss.target import filter as target_filter  # noqa: E402
from ehss.target._kernels import crossfade_block, filter_block  # noqa: E402

FS = 5000.0
CHANNELS = 8


def _compensator(rng, n_sections, n_taps):
    from tests.target.naive import random_compensator
    return random_compensator(rng, n_sections, n_taps, preview=3, fs_hz=FS)


def _rate(n_sections, n_taps, block, seconds, *, fading):
    rng = np.random.default_rng(1)
    filters = [CompensatorFilter(_compensator(rng, n_sections, n_taps)) for _ in
               range(CHANNELS)]
    n = int(seconds * FS)
    x = rng.standard_normal((CHANNELS, n))
    if fading:   # every channel fades in a new compensator over the whole run
        for f in filters:
            f.load(_compensator(rng, n_sections, n_taps), apply_index=0,
                   crossfade=n + 10)
    for f, xi in zip(filters, x, strict=True):   # compile and warm
        f.process(xi[:block])
    t0 = time.perf_counter()
    for start in range(block, n - block + 1, block):
        for f, xi in zip(filters, x, strict=True):
            f.process(xi[start:start + block])
    wall = time.perf_counter() - t0
    return ((n - block) // block * block / FS) / wall


def _c_rate(n_sections, n_taps, seconds):
    try:
        import pathlib
        import tempfile

        from tests.target.test_c import c as fixture
    except ImportError:
        return None

    class _Dirs:
        def mktemp(self, name):
            return pathlib.Path(tempfile.mkdtemp(prefix=name))
    ffi, lib = fixture.__wrapped__(_Dirs())
    from ehss.target import CompensatorUpdate, encode
    rng = np.random.default_rng(1)
    n = int(seconds * FS)
    x = rng.standard_normal(n)
    y = np.empty_like(x)
    states = []
    for ch in range(CHANNELS):
        s = ffi.new("ehss_comp_state *")
        lib.ehss_comp_init(s, ch, 3, FS, 0)
        data = encode(CompensatorUpdate(channel=ch, sequence=1, apply_index=0, crossfade=0,
                                        compensator=_compensator(rng, n_sections, n_taps)))
        lib.ehss_comp_decode(s, data, len(data))
        if ch == 0:
            data0 = data
        states.append(s)
    t0 = time.perf_counter()
    for s in states:
        lib.run_block(s, ffi.from_buffer("double[]", x), ffi.from_buffer("double[]", y), n)
    rate = (n / FS) / (time.perf_counter() - t0)
    # one decode (CRC, checks, the copy into the mailbox) of such a datagram: best of
    # 2000, each on a freshly started channel so that it is taken (a cffi call adds
    # about a tenth of a microsecond)
    s = ffi.new("ehss_comp_state *")
    best = np.inf
    for _ in range(2000):
        lib.ehss_comp_init(s, 0, 3, FS, 0)
        t0 = time.perf_counter()
        lib.ehss_comp_decode(s, data0, len(data0))
        best = min(best, time.perf_counter() - t0)
    return rate, best * 1e6


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=2.0)
    a = p.parse_args()
    print(f"Python {platform.python_version()}, numpy {np.__version__}; "
          f"{CHANNELS} channels at {FS:g} Hz, {a.seconds:g} s of stream per case")
    print("| compensator | block | state | real-time factor (numba) | "
          "interpreted kernel | C, per sample | C decode (µs) |")
    print("|---|---:|---|---:|---:|---:|---:|")
    for n_sections, n_taps in ((4, 32), (16, 256), (16, 1280), (16, MAX_TAPS)):
        c_rate, c_decode = _c_rate(n_sections, n_taps, a.seconds) or (None, None)
        for block in (5, 50):
            for fading in (False, True):
                fast = _rate(n_sections, n_taps, block, a.seconds, fading=fading)
                target_filter.filter_block = filter_block.py_func
                target_filter.crossfade_block = crossfade_block.py_func
                try:
                    slow = _rate(n_sections, n_taps, block, a.seconds / 40, fading=fading)
                finally:
                    target_filter.filter_block = filter_block
                    target_filter.crossfade_block = crossfade_block
                c_text = f"{c_rate:.0f} | {c_decode:.1f}" \
                    if c_rate is not None and not fading else " | "
                print(f"| {n_sections} sections, {n_taps} taps | {block} | "
                      f"{'cross-fade' if fading else 'steady'} | {fast:.1f} | "
                      f"{slow:.3f} | {c_text} |")


if __name__ == "__main__":
    main()
