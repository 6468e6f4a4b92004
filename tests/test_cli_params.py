from __future__ import annotations

from ehss.cli import main


def test_params_prints_table(capsys):
    assert main(["params"]) == 0
    out = capsys.readouterr().out
    assert "hydraulic_freq_hz" in out and "Hz" in out


def test_params_save_and_reload(tmp_path, capsys):
    f = tmp_path / "p.toml"
    assert main(["params", "--preset", "paper", "--save", str(f)]) == 0
    assert main(["params", "--params", str(f)]) == 0
    assert "5000" in capsys.readouterr().out


def test_bad_param_file_exit_2(tmp_path, capsys):
    f = tmp_path / "p.toml"
    f.write_text("[load]\nmass_kg = -5\n")
    assert main(["params", "--params", str(f)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "mass_kg" in err


def test_unknown_preset_exit_2(capsys):
    try:
        main(["params", "--preset", "nope"])
    except SystemExit as exc:
        assert exc.code == 2
    assert "invalid choice" in capsys.readouterr().err


def test_save_onto_the_params_file_is_refused(tmp_path, capsys):
    f = tmp_path / "p.toml"
    f.write_text("[load]\nmass_kg = 300\n")
    assert main(["params", "--params", str(f), "--save", str(f)]) == 2
    assert "would replace the input" in capsys.readouterr().err
    assert f.read_text() == "[load]\nmass_kg = 300\n"
