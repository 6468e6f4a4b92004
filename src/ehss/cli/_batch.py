"""``ehss batch``: identify every channel of every record of an archive, on Dask.

A thin adapter over :func:`ehss.campaign.batch`.
"""

from __future__ import annotations

import argparse
import sys

from ehss.cli import add_command
from ehss.cli._outputs import InputFile, OutputFolder

__all__ = ["register", "run", "add_cluster_arguments", "check_cluster_arguments"]


def add_cluster_arguments(p: argparse.ArgumentParser) -> None:
    """``--scheduler``, ``--workers``, ``--connect-timeout``, ``--quiet``."""
    p.add_argument("--scheduler", metavar="tcp://HOST:8786",
                   help="a running Dask scheduler (default: a local cluster on this machine)")
    p.add_argument("--workers", type=int, metavar="N",
                   help="workers of the local cluster, one thread each (default: one per "
                   "core; 0: in this process)")
    p.add_argument("--connect-timeout", type=float, default=5.0, metavar="S",
                   help="how long to wait for --scheduler (default: %(default)s s)")
    p.add_argument("--quiet", action="store_true",
                   help="no progress bar and no dashboard link")


def check_cluster_arguments(args: argparse.Namespace) -> None:
    """Refuse, before the campaign folder is made, a negative --workers, a --connect-timeout
    that is no time and a --scheduler address Dask has no transport for."""
    from ehss._checks import check_int, check_real
    from ehss.errors import ParameterError

    if args.workers is not None:
        check_int(args.workers, "--workers", lo=0)
    check_real(args.connect_timeout, "--connect-timeout", lo=0.0, lo_open=True, unit="s")
    if args.scheduler is not None:
        from distributed.comm import get_address_host, registry
        from distributed.comm.addressing import parse_address

        try:
            scheme, _ = parse_address(args.scheduler)
            registry.get_backend(scheme)
            get_address_host(args.scheduler)
        except (ValueError, TypeError) as exc:
            raise ParameterError(f"--scheduler {args.scheduler!r} is not a Dask scheduler "
                                 f"address such as tcp://HOST:8786 ({exc})") from None


def _named_records(records: list[str]) -> None:
    """Refuse a record named without a wildcard that does not exist: a typing error, not
    a record of the campaign that failed."""
    import glob
    from pathlib import Path

    from ehss.errors import DataError

    for pattern in records:
        if not glob.has_magic(pattern) and not Path(pattern).exists():
            raise DataError(f"{pattern!r}: no such file")


def register(sub: argparse._SubParsersAction) -> None:
    from ehss.identification import METHODS

    p = add_command(
        sub, "batch",
        description="Identify every channel of every record (files by glob, the groups of "
        "an HDF5 file, ehss live recordings, Parquet files) the same way, with the "
        "identification workflow of `ehss identify`, on a Dask cluster. Writes one "
        "Parquet file of rows per record (OUT/tasks/), the models (OUT/models/) and "
        "OUT/summary.html: trends of the loops' figures over record time and the records "
        "that stand out from the campaign's own spread, with why. A re-run skips the "
        "records already done.",
        epilog="example: ehss batch 'archive/2026/*.h5' --manifest lab.toml --out campaign",
    )
    p.add_argument("records", nargs="*", metavar="RECORD",
                   help="files or globs (quote them); default the manifest's 'records'")
    p.add_argument("--manifest", type=InputFile, metavar="FILE.toml",
                   help="columns, sample rate, channels and workflow settings (README: "
                   "Campaigns)")
    p.add_argument("--out", type=OutputFolder, required=True, metavar="DIR",
                   help="campaign folder (created; an earlier run there is resumed)")
    p.add_argument("--orders", type=int, nargs=4, metavar=("NA", "NB", "NC", "D"),
                   help="model orders for every channel (default: the manifest's, else "
                   "4 3 4 1)")
    p.add_argument("--method", choices=METHODS, help="estimator (default: the manifest's, "
                   "else armax)")
    p.add_argument("--band", type=float, nargs=2, metavar=("LO", "HI"),
                   help="band of interest, Hz (default: wherever the coherence allows)")
    p.add_argument("--fs", type=float, metavar="HZ",
                   help="sample rate of records without a time column")
    add_cluster_arguments(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import polars as pl

    from ehss._checks import check_band
    from ehss.campaign import batch, load_manifest

    check_cluster_arguments(args)
    if args.band is not None:
        check_band(args.band, "--band")
    settings = load_manifest(args.manifest, orders=tuple(args.orders) if args.orders else None,
                             method=args.method, fs=args.fs,
                             band_hz=tuple(args.band) if args.band else None)
    _named_records(args.records)
    frame = batch(args.records or None, args.out, settings=settings,
                  scheduler=args.scheduler, workers=args.workers, quiet=args.quiet,
                  connect_timeout_s=args.connect_timeout)
    ok = frame.filter(pl.col("status") == "ok")
    n_acc = int(ok["accepted"].sum()) if ok.height else 0
    n_flag = int(frame["flagged"].sum())
    print(f"ehss batch: {frame['record'].n_unique()} records, {frame.height} channel rows: "
          f"{ok.height} identified ({n_acc} meet the acceptance), "
          f"{frame.height - ok.height} failed, {n_flag} flagged; rows in "
          f"{args.out}/tasks/, summary {args.out}/summary.html")
    for r in frame.filter(pl.col("status") != "ok").iter_rows(named=True):
        print(f"  failed: {r['record']} channel {r.get('channel') or '-'}: {r['error']}",
              file=sys.stderr)
    return 0
