"""ehss live / ehss stream: bad input is one line on stderr and exit 2."""

from __future__ import annotations

import pytest

from ehss.cli import main


@pytest.mark.parametrize("argv, word", [
    (["live", "--udp", "localhost:5005", "--fields", "t,ref1,fb1"], "IPv4:PORT"),
    (["live", "--udp", "127.0.0.1:99999", "--fields", "t,ref1,fb1"], "PORT"),
    (["live", "--udp", "127.0.0.1:0"], "--fields"),
    (["live", "--udp", "127.0.0.1:0", "--fields", "t,ref1"], "fb1"),
    (["live", "--udp", "127.0.0.1:0", "--fields", "t,ref1,fb1", "--allow", "x"], "allow"),
    (["live", "--rig", "position", "--event", "soon:mass_kg=3"], "T:NAME=VALUE"),
    (["live", "--rig", "position", "--event", "3:weight=3"], "weight"),
    (["live", "--rig", "position", "--event", "3:mass_kg=-3"], "mass_kg"),
    (["live", "--rig", "position", "--channels", "2", "--event", "3:mass_kg=3@9"],
     "channel"),
    (["live", "--rig", "position", "--speed", "0"], "--speed"),
    (["live", "--rig", "position", "--frf-db", "0"], "frf_db"),
    (["live", "--rig", "position", "--memory", "-1"], "memory_s"),
    (["live", "--replay", "no-such-file.csv"], "no such file"),
    (["stream", "--to", "127.0.0.1", "--rig", "position"], "IPv4:PORT"),
    # --duration is the simulated rig's: a received or replayed stream would ignore it
    (["live", "--udp", "127.0.0.1:0", "--fields", "t,ref1,fb1", "--duration", "10"],
     "--stop-after S stops the run"),
    (["live", "--udp", "127.0.0.1:0", "--fields", "t,ref1,fb1", "--event", "3:mass_kg=3"],
     "--event applies to --rig only"),
    (["stream", "--to", "127.0.0.1:9", "--replay", "no-such-file.csv", "--duration", "5"],
     "--duration applies to --rig only"),
])
def test_bad_input_exits_2_with_one_line(argv, word, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and word in err, err


def test_recording_is_never_overwritten(tmp_path, capsys):
    rec = tmp_path / "run.h5"
    rec.write_bytes(b"keep")
    assert main(["live", "--rig", "position", "--duration", "1", "--speed", "inf",
                 "--quiet", "--record", str(rec)]) == 2
    assert rec.read_bytes() == b"keep"
    assert "never overwritten" in capsys.readouterr().err


def test_help_documents_the_wire_format(capsys):
    with pytest.raises(SystemExit):
        main(["live", "--help"])
    out = capsys.readouterr().out
    for word in ("magic", "uint16", "uint64", "little-endian", "ref<k>", "fb<k>"):
        assert word in out


def test_rig_run_writes_a_report(tmp_path, capsys):
    import json

    assert main(["live", "--rig", "position", "--channels", "2", "--duration", "3",
                 "--speed", "inf", "--learn", "1", "--quiet",
                 "--report", str(tmp_path / "r.json")]) == 0
    r = json.loads((tmp_path / "r.json").read_text())
    assert r["samples"] == 3000 and r["counters"]["lost_samples"] == 0
    assert set(r["final_theta"]) == {"1", "2"}
    assert len(r["final_theta"]["1"]) == 4 + 4 + 4  # a1..a4, b0..b3, c1..c4


def test_a_rig_run_too_short_for_its_fades_is_one_clear_line(capsys):
    assert main(["live", "--rig", "position", "--duration", "0.3", "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["ehss live: error: duration_s=0.3 is too short: the rig's reference fades "
                   "in and out over 0.2 s at each end, so at least 0.4 s"]
