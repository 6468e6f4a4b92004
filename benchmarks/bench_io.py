"""Writing and reading a simulate record: the table writers and the record readers.

The record is what ``ehss simulate`` writes for a 600 s test at 1 kHz: 21 float64 columns
(t, reference, output, then every internal signal), produced by ``ehss.simulate`` on a
seeded band-limited random position test. In one run, best of ``--repeat`` runs each:

Writing, into the same folder:

- ``baseline``: the CSV writer as it was (``repr`` of every value, joined into one
  string in Python) -- kept here, verbatim, as the reference;
- ``ehss.io.write_table`` to ``.csv`` (+ JSON sidecar), ``.parquet``, ``.h5``,
  ``.npz`` and ``.mat``, all carrying the same metadata.

Reading, every column of each of those files, and of the record as a semicolon file with
decimal commas and as a headerless whitespace-separated ``.dat`` (DaISy's layout), with
``ehss.io.read_columns`` and, given ``--against READERS.py`` (an earlier
``src/ehss/io/readers.py``, e.g. ``git show REV:src/ehss/io/readers.py``), with that
reader too, the two alternating so that both see the same load.

Every file read is compared bit for bit with the record, so the speed is not bought
with precision.

Usage::

    python benchmarks/bench_io.py [--duration 600] [--repeat 3] [--against OLD.py]
                                  [--markdown out.md]
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import platform
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def _cpu_model() -> str:
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def baseline_write_csv(path: Path, columns: dict[str, np.ndarray]) -> None:
    """The previous ``ehss.io.write_csv`` body: ``repr`` per value, joined in Python."""
    arrays = {name: np.asarray(v).astype(np.float64, copy=False) for name, v in columns.items()}
    lines: list[str] = [",".join(arrays)]
    rows = zip(*(a.tolist() for a in arrays.values()), strict=True)
    lines.extend(",".join(map(repr, row)) for row in rows)
    text = "\n".join(lines) + "\n"
    path.write_text(text, encoding="utf-8")


def _record(duration_s: float) -> tuple[dict[str, np.ndarray], dict]:
    from ehss import signals, simulate

    fs = 1000.0
    sig = signals.band_limited_random(band_hz=(1.0, 20.0), peak=1e-3, seed=0,
                                      duration_s=duration_s, fs=fs)
    result = simulate("position", sig.values, fs=fs, seed=0)
    meta = {"loop": "position", "fs_hz": fs, "seed": 0, "units": result.units}
    return result.to_columns(), meta


def _best_of(fn, repeat: int) -> float:
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def _load_reader(path: Path):
    """``read_columns`` of an earlier readers module, loaded from its file."""
    spec = importlib.util.spec_from_file_location("ehss_bench_earlier_readers", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module.read_columns


def _text_variants(folder: Path, cols: dict[str, np.ndarray]) -> list[Path]:
    """The record as a semicolon file with decimal commas and as a headerless
    whitespace-separated file (``repr`` of each value: read back exactly)."""
    rows = np.column_stack(list(cols.values())).tolist()
    eu = folder / "run_eu.csv"
    with open(eu, "w", encoding="utf-8") as fh:
        fh.write(";".join(cols) + "\n")
        fh.writelines(";".join(repr(x) for x in row).replace(".", ",") + "\n"
                      for row in rows)
    dat = folder / "run.dat"
    with open(dat, "w", encoding="utf-8") as fh:
        fh.writelines("".join(f"{x!r:>26}" for x in row) + "\n" for row in rows)
    return [eu, dat]


def _check_exact(path: Path, back, cols: dict[str, np.ndarray]) -> None:
    values = list(back.values()) if path.suffix == ".dat" else [back[k] for k in cols]
    if not all(np.array_equal(a.view(np.int64), v.view(np.int64))
               for a, v in zip(values, cols.values(), strict=True)):
        raise SystemExit(f"{path.name}: read back differs from the record")


def _read_rows(paths: list[Path], cols: dict[str, np.ndarray], repeat: int,
               earlier) -> list[tuple[str, float, float | None]]:
    """(file, best new time, best earlier time or None) for reading every column."""
    from ehss.io import read_columns

    rows = []
    for path in paths:
        readers = [read_columns] + ([earlier] if earlier is not None else [])
        if path.suffix == ".parquet":
            readers = [read_columns]  # the same polars call before and after
        best = [np.inf] * len(readers)
        for _ in range(repeat):
            for k, read in enumerate(readers):  # alternate: both see the same load
                t0 = time.perf_counter()
                back = read(path)
                best[k] = min(best[k], time.perf_counter() - t0)
                _check_exact(path, back, cols)
        rows.append((path.name, best[0], best[1] if len(best) > 1 else None))
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=600.0, help="seconds at 1 kHz")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--against", type=Path, help="an earlier readers.py to compare with")
    ap.add_argument("--markdown", type=Path, help="also write the tables there")
    args = ap.parse_args(argv)

    import polars
    import scipy

    from ehss.io import read_columns, write_table

    earlier = _load_reader(args.against) if args.against else None
    cols, meta = _record(args.duration)
    n = next(iter(cols.values())).size
    folder = Path(tempfile.mkdtemp(prefix="ehss-bench-io-"))
    try:
        rows = []
        path = folder / "baseline.csv"
        t_base = _best_of(lambda: baseline_write_csv(path, cols), args.repeat)
        rows.append(("baseline: repr + join (previous write_csv)", t_base,
                     path.stat().st_size))
        for ext in ("csv", "parquet", "h5", "npz", "mat"):
            path = folder / f"run.{ext}"
            t = _best_of(lambda p=path: write_table(p, cols, meta), args.repeat)
            back = read_columns(path)
            exact = all(np.array_equal(back[k].view(np.int64), v.view(np.int64))
                        for k, v in cols.items())
            if not exact:
                raise SystemExit(f"{path.name}: read back differs from the record")
            size = path.stat().st_size
            rows.append((f"write_table .{ext}", t, size))
        written = [folder / f"run.{ext}" for ext in ("csv", "parquet", "h5", "npz", "mat")]
        read_rows = _read_rows(written + _text_variants(folder, cols), cols, args.repeat,
                               earlier)
    finally:
        shutil.rmtree(folder, ignore_errors=True)

    lines = [
        f"{len(cols)} columns x {n} rows ({args.duration:g} s at 1 kHz, ehss.simulate "
        f"position loop), best of {args.repeat}; every file read back bit-exact",
        "",
        "| writer | wall time (s) | file size (MB) | speed-up vs baseline |",
        "|---|---:|---:|---:|",
    ]
    for name, t, size in rows:
        lines.append(f"| {name} | {t:.3f} | {size / 1e6:.1f} | {t_base / t:.1f}× |")
    lines += [
        "",
        "| file (every column read) | read_columns (s) | earlier reader (s) | speed-up |",
        "|---|---:|---:|---:|",
    ]
    for name, t_new, t_old in read_rows:
        old = "—" if t_old is None else f"{t_old:.3f}"
        gain = "—" if t_old is None else f"{t_old / t_new:.1f}×"
        lines.append(f"| {name} | {t_new:.3f} | {old} | {gain} |")
    lines += [
        "",
        f"- Machine: {os.cpu_count()} cores, {_cpu_model()}; Python "
        f"{platform.python_version()}, numpy {np.__version__}, polars {polars.__version__}, "
        f"scipy {scipy.__version__}; load average "
        f"{', '.join(f'{x:.1f}' for x in os.getloadavg())} at the end.",
        f"- Command: `python benchmarks/bench_io.py --duration {args.duration:g} "
        f"--repeat {args.repeat}"
        + (f" --against {args.against}`" if args.against else "`"),
    ]
    text = "\n".join(lines)
    print(text)
    if args.markdown:
        args.markdown.write_text(text + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
