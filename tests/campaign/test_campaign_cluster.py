"""Campaigns on a real Dask cluster on localhost: the same rows as one process, whatever
happens to the workers or the client."""

from __future__ import annotations

import signal

import polars as pl
import pytest

from ehss.campaign import read_results

from .conftest import (
    N_RECORDS,
    Cluster,
    make_archive,
    popen_cli,
    run_cli,
    start,
    start_worker,
    stop,
    wait_for_files,
    wait_for_workers,
)

pytestmark = pytest.mark.slow

# Columns that differ between two campaign folders by construction: none of the rows'
# own values (record, channel, figures, coefficients, model file's relative name) do.
SORT = ("record", "channel")


def rows(out) -> pl.DataFrame:
    return read_results(out, sort_by=SORT)


def assert_same_rows(out, reference: pl.DataFrame) -> None:
    got = rows(out)
    assert got.height == N_RECORDS  # one row per record and channel: none lost
    assert got["record"].n_unique() == N_RECORDS  # and none twice
    # bit for bit: the same floats, not merely close ones (each task's seed and its one
    # BLAS thread make the numbers independent of the worker and the order)
    assert got.equals(reference.drop("flagged", "flag_reason"))


def test_cluster_run_equals_single_process(cluster, archive, reference, tmp_path):
    assert reference["status"].to_list() == ["ok"] * N_RECORDS
    out = tmp_path / "c"
    res = run_cli("batch", "--manifest", str(archive), "--out", str(out),
                  "--scheduler", cluster.address, "--quiet")
    assert res.returncode == 0, res.stderr
    assert f"{N_RECORDS} identified" in res.stdout
    assert_same_rows(out, reference)
    assert (out / "summary.html").is_file()


def test_worker_killed_mid_run(cluster, archive, reference, tmp_path):
    extra = start_worker(cluster.address, tmp_path / "extra.log")
    try:
        wait_for_workers(cluster.address, 3)
        out = tmp_path / "k"
        proc = popen_cli("batch", "--manifest", str(archive), "--out", str(out),
                         "--scheduler", cluster.address, "--quiet")
        done = wait_for_files(out / "tasks", 40, proc)
        stop(extra, signal.SIGKILL)  # the worker and its nanny, at once
        assert done < N_RECORDS  # killed while the campaign ran
        _, err = proc.communicate(timeout=120)
        assert proc.returncode == 0, err
    finally:
        stop(extra, signal.SIGKILL)
    assert_same_rows(out, reference)


def test_interrupt_then_resume(cluster, archive, reference, tmp_path):
    out = tmp_path / "i"
    args = ("batch", "--manifest", str(archive), "--out", str(out), "--scheduler",
            cluster.address, "--quiet")
    proc = popen_cli(*args)
    wait_for_files(out / "tasks", 20, proc)
    proc.send_signal(signal.SIGINT)  # Ctrl-C
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert err.strip().splitlines()[-1] == "ehss batch: interrupted"
    before = {p.name for p in (out / "tasks").glob("[!.]*.parquet")}
    assert 0 < len(before) < N_RECORDS
    res = run_cli(*args)
    assert res.returncode == 0, res.stderr
    after = {p.name for p in (out / "tasks").glob("[!.]*.parquet")}
    assert before < after and len(after) == N_RECORDS
    assert_same_rows(out, reference)


def test_unreachable_scheduler_is_one_line(tmp_path):
    from .conftest import free_port

    (tmp_path / "x.csv").write_text("")  # a record named on the command line must exist
    res = run_cli("batch", "--out", str(tmp_path / "u"), "--scheduler",
                  f"tcp://127.0.0.1:{free_port()}", "--connect-timeout", "0.5",
                  str(tmp_path / "x.csv"), timeout=60)
    assert res.returncode == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "cannot reach the Dask scheduler" in lines[0], res.stderr
    assert not (tmp_path / "u").exists()  # nothing left behind for a run that never began


def test_worker_without_ehss_records_the_error(tmp_path):
    """Every task sent to a worker that cannot import ehss gets one error row naming it;
    none is lost."""
    archive = make_archive(tmp_path / "a", n=5)
    blocked = tmp_path / "noehss.py"
    blocked.write_text("import sys\nsys.modules['ehss'] = None  # this worker lacks ehss\n"
                       "from dask.cli import run_cli\n"
                       "sys.argv = ['dask', 'worker', *sys.argv[1:]]\nrun_cli()\n")
    c = Cluster(tmp_path, 0)
    try:
        import sys

        c.procs.append(start([sys.executable, str(blocked), c.address, "--no-nanny",
                              "--nthreads", "1", "--no-dashboard"], tmp_path / "noehss.log"))
        wait_for_workers(c.address, 1)
        out = tmp_path / "o"
        res = run_cli("batch", "--manifest", str(archive), "--out", str(out),
                      "--scheduler", c.address, "--quiet")
    finally:
        c.close()
    assert res.returncode == 0, res.stderr
    got = rows(out)
    assert got.height == 5 and got["status"].to_list() == ["error"] * 5
    for e in got["error"]:
        assert "\n" not in e and "No module named 'ehss" in e and "install ehss" in e
