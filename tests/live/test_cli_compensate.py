"""ehss live --compensate: the simulated rig with adaptive compensation, from the CLI."""

from __future__ import annotations

import json

import numpy as np
import pytest

from ehss.cli import main


@pytest.mark.slow
def test_compensated_rig_run_reports_and_records_its_figures(tmp_path, capsys):
    from ehss.live import read_recording

    report, record = tmp_path / "run.json", tmp_path / "run.h5"
    argv = ["live", "--rig", "position", "--channels", "2", "--duration", "8",
            "--band", "0.5", "20", "--compensate", "preview", "--speed", "inf",
            "--max-gain", "3.5", "--memory", "0.4", "--report", str(report),
            "--record", str(record), "--quiet"]
    assert main(argv) == 0
    err = capsys.readouterr().err
    assert "compensating (preview, FIR of 256 taps, 128 samples ahead), band 0.5-20 Hz" \
        in err and "channel 2: tracking RMS" in err
    out = json.loads(report.read_text())
    assert out["compensation"]["mode"] == "preview"
    assert out["compensation"]["max_gain"] == 3.5
    assert out["compensation"]["memory_s"] == 0.4      # the compensators' estimators too
    for name in ("1", "2"):
        ch = out["channels"][name]
        assert ch["loads"] > 0
        # the rig's 1 mm reference asks for drives near the rig's velocity limit, which
        # the guard refuses (3 to 12 times better than without on this 8 s run, 12 to
        # 45 times over 30 s; tests/live/test_adaptive_rig.py measures the figures)
        assert ch["tracking_rms"] < ch["tracking_rms_without"] / 2
    assert all(load["accepted"] for load in out["loads"])
    # the live session ran inside: its figures in the report, and the recording holds
    # the desired reference beside the drive and every compensator sent
    assert out["samples"] == 8000 and out["counters"]["lost_samples"] == 0
    rec = read_recording(record)
    assert rec["fields"] == ["t", "ref1", "fb1", "des1", "ref2", "fb2", "des2"]
    assert rec["samples"].shape == (8000, 7)
    sent = [e for e in rec["events"] if e["kind"] == "compensator"]
    assert len(sent) == len(out["loads"])
    # the drive differs from the desired reference once a compensator is in
    x = rec["samples"][-1000:]
    assert not np.allclose(x[:, 1], x[:, 3])


@pytest.mark.parametrize("argv, word", [
    (["live", "--udp", "127.0.0.1:0", "--fields", "t,ref1,fb1", "--compensate", "causal"],
     "--target"),
    (["live", "--udp", "127.0.0.1:0", "--fields", "t,ref1,fb1", "--fs", "1000", "--band",
      "0.5", "20", "--rms", "0.001", "--target", "127.0.0.1:9", "--compensate",
      "preview"], "des1"),
    (["live", "--rig", "position", "--rms", "0.001"], "--compensate only"),
    (["live", "--rig", "position", "--max-gain", "4"], "--compensate only"),
    (["live", "--rig", "position", "--compensate", "preview", "--max-gain", "0.5"],
     "--max-gain"),
    (["live", "--rig", "position", "--compensate", "preview", "--max-gain", "inf"],
     "--max-gain"),
    (["live", "--rig", "position", "--taps", "512"], "--compensate only"),
    (["live", "--rig", "position", "--compensate", "preview", "--taps", "4096"], "--taps"),
    (["live", "--rig", "position", "--compensate", "preview", "--taps", "0"], "--taps"),
    (["live", "--rig", "position", "--compensate", "preview", "--fs", "nan"], "--fs"),
    (["live", "--rig", "position", "--compensate", "preview", "--fs", "inf"], "--fs"),
    (["live", "--rig", "position", "--compensate", "preview", "--band", "5", "nan"],
     "--band 5 nan"),
    (["live", "--rig", "position", "--compensate", "preview", "--band", "1", "600"],
     "--band 1 600"),
])
def test_bad_compensation_input_exits_2_with_one_line(argv, word, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and word in err, err



def test_a_rig_reference_beyond_the_rigs_limits_stops_before_the_run(tmp_path, capsys):
    import ehss
    from ehss.cli._live_compensate import _check_within_limits
    from ehss.live.rig import rig_reference

    # 1 mm over 1-30 Hz peaks at about 0.43 m/s on the position loop, over its 0.2 m/s:
    # every compensator would be refused, so the run does not start
    report = tmp_path / "run.json"
    argv = ["live", "--rig", "position", "--duration", "10", "--band", "1", "30",
            "--rms", "0.001", "--compensate", "preview", "--speed", "inf",
            "--report", str(report), "--quiet"]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert "beyond the rig's limits" in err and "max_velocity_m_s" in err, err
    assert not report.exists()
    # the same reference at a quarter of the level is within them
    params = ehss.preset("default")
    fs = params.timing.control_rate_hz
    quarter = rig_reference(10_000, fs, band_hz=(1.0, 30.0), rms=2.5e-4, seed=1)
    _check_within_limits(quarter[None, :], fs, "position", params, 2.5e-4, (1.0, 30.0))
    with pytest.raises(ehss.ParameterError, match="channel 1's reference"):
        _check_within_limits(4 * quarter[None, :], fs, "position", params, 1e-3, (1.0, 30.0))


@pytest.mark.slow
def test_a_change_flagged_and_its_correction_are_printed(capsys):
    # +40 % payload on channel 1 at 10 s: the compensator's trigger (calibrated on the
    # blocks of the seconds before) flags it within a second, and the line reaches the
    # user as it happens, with the compensator that follows it
    argv = ["live", "--rig", "position", "--channels", "2", "--duration", "16",
            "--band", "0.5", "20", "--rms", "0.0005", "--event", "10:mass_kg=350@1",
            "--compensate", "preview", "--speed", "inf", "--quiet"]
    assert main(argv) == 0
    lines = [json.loads(line.removeprefix("ehss live: "))
             for line in capsys.readouterr().err.splitlines()
             if line.startswith("ehss live: {")]
    changes = [e for e in lines if e["kind"] == "compensator_change"]
    assert [e["channel"] for e in changes] == ["1"]
    assert 10.0 < changes[0]["t_s"] <= 11.0
    # and the compensators that follow it on channel 1: a correction of the running
    # one, or models refitted on the data since the change (``refit_rows`` of them)
    after = [e for e in lines if e["kind"] == "compensator" and e["channel"] == "1"
             and e["t_s"] > changes[0]["t_s"]]
    assert any(e.get("model") == "correction"
               or 0 < e.get("refit_rows", 0) <= (e["t_s"] - 10.0) * 1000 for e in after)
    # and the loop, healthy, raises no compensator alarm while its change is followed:
    # a model kept out only because the running compensator is better is no fault
    assert not [e for e in lines if e["kind"] == "compensator_alarm"]


def test_a_band_beyond_the_loop_is_compensated_up_to_where_the_drive_passes(capsys):
    # a band up to 100 Hz, far above the position loop's, asks for drives tens of times
    # the reference's RMS (within the rig's limits at 0.05 mm): the first judgements are
    # refused for it, and after three in a row the models' inverses are loaded up to
    # where their drive passes, which the summary says; a channel on which nothing is
    # loaded says why (below)
    argv = ["live", "--rig", "position", "--channels", "1", "--duration", "5", "--band",
            "0.5", "100", "--rms", "0.00005", "--compensate", "preview", "--speed", "inf",
            "--quiet"]
    assert main(argv) == 0
    err = capsys.readouterr().err
    lines = [json.loads(x[len("ehss live: "):]) for x in err.splitlines()
             if x.startswith("ehss live: {")]
    over = [e for e in lines if e["kind"] == "compensator_refused"
            and e["reason"].startswith("the drive's RMS is")]
    loads = [e for e in lines if e["kind"] == "compensator"]
    # (a refusal for the same reason as the one before is not printed again)
    assert over and "(bound 3×)" in over[0]["reason"]
    assert loads and all(0.5 < e["narrowed_to_hz"] < 100.0 for e in loads)
    assert all(e["t_s"] > over[-1]["t_s"] for e in loads)
    summary = next(x for x in err.splitlines() if "tracking RMS over the second half" in x)
    assert f"{len(loads)} of them up to" in summary and "beyond --max-gain" in summary
    assert "no compensator was loaded" not in err


def test_models_refused_by_the_h1_estimate_point_to_the_band(capsys):
    from types import SimpleNamespace

    from ehss.cli._live_compensate import _compare
    from ehss.compensation.adaptive import H1_DISAGREES

    n, fs = 2000, 1000.0
    desired = np.ones((2, n))
    miss = f"{H1_DISAGREES} by 1.13 dB / 22.9° beyond its uncertainty"
    others = ["no H1 estimate to confirm the model yet",
              "the model is unstable (pole radius 1.01)"]
    rec = SimpleNamespace(
        desired=desired, feedback=np.zeros((2, n)), fs=fs, channels=("1", "2"), loads=[],
        decisions={"1": [{"accepted": False, "reason": miss}] * 3,
                   "2": [{"accepted": False, "reason": r} for r in [miss, *others]]},
        tracking_rms=lambda t0, t1: np.ones(2))
    out = _compare(rec, [])
    assert out["1"]["latest_refusal"] == miss and out["2"]["refusals"] == 3
    lines = {x.split(":")[1].strip(): x for x in capsys.readouterr().err.splitlines()
             if "no compensator was loaded" in x}
    # most of channel 1's refusals are the H1 estimate's: the band is the thing to try;
    # on channel 2 they are not
    assert "--band" in lines["channel 1"]
    assert "--band" not in lines["channel 2"] and "unstable" in lines["channel 2"]


def test_where_the_models_missed_the_h1_estimate_is_said(capsys):
    # channel 1: 5 judgements, 4 refused as the model missed the H1 estimate, 3 of them
    # furthest at 4.88 Hz (a band's lower edge) and one at 48.8 Hz; channel 2: one such
    # refusal of three, which says nothing of where its models miss
    from types import SimpleNamespace

    from ehss.cli._live_compensate import _compare
    from ehss.compensation.adaptive import H1_DISAGREES

    def miss(hz):
        return {"accepted": False, "reason": f"{H1_DISAGREES} by ...", "h1_worst_hz": hz}

    n = 2000
    rec = SimpleNamespace(
        desired=np.ones((2, n)), feedback=np.zeros((2, n)), fs=1000.0, channels=("1", "2"),
        loads=[{"channel": "1", "model": "estimator"}, {"channel": "2", "model": "tracker"}],
        decisions={"1": [{"accepted": True}, miss(4.88), miss(48.8), miss(4.88), miss(4.88)],
                   "2": [miss(20.0), {"accepted": False, "reason": "unstable"},
                         {"accepted": False, "reason": "unstable"}]},
        tracking_rms=lambda t0, t1: np.ones(2))
    out = _compare(rec, [])
    assert out["1"]["h1_misses"] == {"refusals": 4, "furthest_hz": 4.88, "furthest_there": 3}
    assert "h1_misses" not in out["2"]
    err = capsys.readouterr().err
    assert ("4 refused, 4 of them as the model missed the H1 estimate, most (3) furthest "
            "at 4.88 Hz") in err
    assert "channel 2: tracking RMS" in err and err.count("missed the H1") == 1


def test_loads_narrowed_below_the_bands_top_are_said(capsys):
    # channel 1: three loads, two narrowed (to 70.3 and 74.2 Hz) as their drive over
    # the band was beyond the gain bound; channel 2: none narrowed
    from types import SimpleNamespace

    from ehss.cli._live_compensate import _compare

    n = 2000
    rec = SimpleNamespace(
        desired=np.ones((2, n)), feedback=np.zeros((2, n)), fs=4000.0, channels=("1", "2"),
        loads=[{"channel": "1", "model": "estimator", "narrowed_to_hz": 74.2},
               {"channel": "1", "model": "estimator"},
               {"channel": "1", "model": "tracker", "narrowed_to_hz": 70.3},
               {"channel": "2", "model": "estimator"}],
        decisions={"1": [{"accepted": True}] * 3, "2": [{"accepted": True}]},
        tracking_rms=lambda t0, t1: np.ones(2))
    out = _compare(rec, [])
    assert out["1"]["narrowed"] == {"loads": 2, "lowest_top_hz": 70.3, "highest_top_hz": 74.2}
    assert "narrowed" not in out["2"]
    err = capsys.readouterr().err
    assert ("3 compensators loaded (2 of them up to 70.3-74.2 Hz only: over the whole band "
            "their drive was beyond --max-gain or the rig's limits), 0 refused") in err
    assert err.count("up to") == 1


def test_a_remote_target_that_ran_none_of_its_compensators_is_said_so(capsys):
    from types import SimpleNamespace

    from ehss.cli._live_compensate import _compare

    n = 2000
    why = "channel 2: the target's drive is still its desired reference ..."
    rec = SimpleNamespace(
        desired=np.ones((2, n)), feedback=np.zeros((2, n)), fs=1000.0, channels=("1", "2"),
        loads=[{"channel": c, "model": "estimator"} for c in ("1", "2")],
        decisions={"1": [{"accepted": True}], "2": [{"accepted": True}]},
        tracking_rms=lambda t0, t1: np.ones(2))
    out = _compare(rec, [], {1: why})
    assert out["2"]["ignored_by_target"] == why and "ignored_by_target" not in out["1"]
    err = capsys.readouterr().err.splitlines()
    assert f"ehss live: {why}" in err


def test_models_refused_for_their_gain_point_to_the_band_and_near_misses_to_the_bound(
        capsys):
    from types import SimpleNamespace

    from ehss.cli._live_compensate import _compare

    n = 2000

    def over(what, gain):
        return (f"the drive's {what} is {gain:.3g}× the reference's (bound 3×): the inverse "
                "amplifies where the model is not to be trusted; narrow the band or "
                "re-identify")

    rec = SimpleNamespace(
        desired=np.ones((2, n)), feedback=np.zeros((2, n)), fs=1000.0, channels=("1", "2"),
        loads=[],
        decisions={"1": [{"accepted": False, "reason": r}
                         for r in (over("RMS", 3.12), over("peak", 3.47), over("RMS", 3.3))],
                   "2": [{"accepted": False, "reason": r}
                         for r in (over("RMS", 37.8), over("RMS", 78.3))]},
        tracking_rms=lambda t0, t1: np.ones(2))
    _compare(rec, [])
    lines = {x.split(":")[1].strip(): x for x in capsys.readouterr().err.splitlines()
             if "no compensator was loaded" in x}
    # within twice the bound (a near miss): the bound that would let them through;
    # beyond it, the band alone
    assert "up to 3.47×" in lines["channel 1"] and "--max-gain 3.5 would" in lines["channel 1"]
    assert "up to 78.3×" in lines["channel 2"] and "narrower --band" in lines["channel 2"]
    assert "would let them through" not in lines["channel 2"]

def test_a_channel_whose_later_drives_were_over_the_gain_bound_says_so(capsys):
    # compensators ran on both channels; channel 1's later models all asked more drive
    # than the bound (a change that slowed the loop), channel 2 had two such refusals
    # among its loads, as a healthy rig's peaks do now and then: only channel 1 says so
    from types import SimpleNamespace

    from ehss.cli._live_compensate import _compare

    def over(t_s, gain):
        return {"accepted": False, "t_s": t_s,
                "reason": f"the drive's RMS is {gain:.3g}× the reference's (bound 3×): the "
                          "inverse amplifies where the model is not to be trusted; narrow "
                          "the band or re-identify"}

    ok = {"accepted": True, "t_s": 1.0, "reason": ""}
    rec = SimpleNamespace(
        desired=np.ones((2, 2000)), feedback=np.zeros((2, 2000)), fs=1000.0,
        channels=("1", "2"),
        loads=[{"channel": c, "model": "estimator", "t_s": 1.0} for c in "12"],
        decisions={"1": [ok, over(21.5, 3.22), over(22.0, 3.88),
                         {"accepted": False, "t_s": 22.5, "reason": "a model refused"},
                         over(24.0, 3.41)],
                   "2": [ok, over(5.0, 3.1), over(9.0, 3.05), ok]},
        tracking_rms=lambda t0, t1: np.ones(2))
    out = _compare(rec, [])
    assert out["1"]["over_gain"] == {"refusals": 3, "max_ratio": 3.88, "bound": 3.0,
                                     "latest_t_s": 24.0}
    assert "over_gain" not in out["2"]
    line = next(x for x in capsys.readouterr().err.splitlines() if "refusals were" in x)
    assert line.startswith("ehss live: channel 1: 3 of its 4 refusals were drives over "
                           "--max-gain 3× (up to 3.88×), the latest at 24.00 s")
    assert "narrower --band" in line and "--max-gain 3.9 would let them through" in line


def test_a_channel_switched_off_says_so_with_the_reason(capsys):
    from types import SimpleNamespace

    from ehss.cli._live_compensate import _compare

    n = 2000
    text = "the drive of the compensator that ran failed the checks (peak rate): ..."
    rec = SimpleNamespace(
        desired=np.ones((2, n)), feedback=np.zeros((2, n)), fs=1000.0, channels=("1", "2"),
        loads=[{"channel": "1", "model": "estimator", "t_s": 0.5},
               {"channel": "1", "model": "off", "t_s": 1.25, "text": text}],
        decisions={"1": [{"accepted": True, "reason": ""}], "2": []},
        tracking_rms=lambda t0, t1: np.ones(2))
    out = _compare(rec, [])
    assert out["1"]["switched_off"] == 1 and "switched_off" not in out["2"]
    line = next(x for x in capsys.readouterr().err.splitlines() if "switched off" in x)
    assert line.startswith("ehss live: channel 1:") and "1.25 s" in line and text in line

#: Each loop whose default reference changes when it is compensated: the run's length
#: (s), the band said, and the least gain over no compensation. The position loop's 1 mm
#: over 1-50 Hz played for detection asks for drives every guard refuses; below 3 Hz the
#: acceleration loop's 0.5 Hz high-passes shape it, which the online model misses (1-50
#: Hz: 5.5-9.7x over the second half of 30 s; 3-50 Hz: 11-21x, seeds 0-2; 11.1x here).
DEFAULT_REFERENCES = {"position": (6, "0.5-20 Hz", 10.0), "acceleration": (12, "3-50 Hz", 8.0)}


@pytest.mark.parametrize("loop", sorted(DEFAULT_REFERENCES))
def test_a_rig_compensated_with_its_defaults_loads(loop, tmp_path, capsys):
    # without --band and --rms each loop is compensated over the band it can be
    duration, band, gain = DEFAULT_REFERENCES[loop]
    report = tmp_path / "run.json"
    argv = ["live", "--rig", loop, "--channels", "1", "--duration", str(duration),
            "--compensate", "preview", "--speed", "inf", "--quiet", "--report", str(report)]
    assert main(argv) == 0
    assert f"samples ahead), band {band}" in capsys.readouterr().err
    ch = json.loads(report.read_text())["channels"]["1"]
    assert ch["loads"] > 0 and ch["tracking_rms"] < ch["tracking_rms_without"] / gain


def test_compensating_a_loop_its_gains_leave_unstable_stops_before_the_run(tmp_path, capsys):
    # the paper's printed gains leave its position loop unstable (pole radius 1.02): the
    # rig runs into its limits and follows no reference, so there is no inverse to adapt
    report, record = tmp_path / "run.json", tmp_path / "run.h5"
    argv = ["live", "--rig", "position", "--preset", "paper", "--duration", "3",
            "--compensate", "preview", "--speed", "inf", "--report", str(report),
            "--record", str(record), "--quiet"]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert "position loop is unstable" in err and "--tune" in err, err
    assert not report.exists() and not record.exists()


def test_the_rigs_default_band_follows_a_low_rate(capsys):
    # at 40 Hz the position rig's 0.5-20 Hz would reach fs/2: its top comes down to
    # fs/3, where the inverse's band limit ends at fs/2, and the line says so
    argv = ["live", "--rig", "position", "--channels", "1", "--duration", "4", "--fs", "40",
            "--compensate", "preview", "--speed", "inf", "--quiet"]
    assert main(argv) == 0
    err = capsys.readouterr().err
    assert "default band 0.5-20 Hz ends at fs/3 = 13.3 Hz" in err
    assert "samples ahead), band 0.5-13.3 Hz" in err
    # a band whose bottom does not leave room below fs/3 stops with one line
    argv = ["live", "--rig", "acceleration", "--channels", "1", "--duration", "4",
            "--fs", "8", "--compensate", "preview", "--speed", "inf", "--quiet"]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--fs 8" in err[0] and "--band" in err[0], err
