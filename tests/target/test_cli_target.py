"""``ehss target-code``: the C files and the note written out, never over a file."""

from __future__ import annotations

from pathlib import Path

from ehss.cli import main
from ehss.target.code import TARGET_FILES, target_code_files

DOCS = Path(__file__).resolve().parents[2] / "docs" / "target.md"


def test_writes_the_c_files_and_the_note(tmp_path, capsys):
    out = tmp_path / "target"
    assert main(["target-code", "--out", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == sorted(TARGET_FILES)
    for name, text in target_code_files().items():
        assert (out / name).read_text(encoding="utf-8") == text
    assert "ehss_compensator.c" in capsys.readouterr().out


def test_never_replaces_a_file(tmp_path, capsys):
    (tmp_path / "ehss_compensator.c").write_text("mine")
    assert main(["target-code", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "ehss_compensator.c" in err and "Traceback" not in err
    assert (tmp_path / "ehss_compensator.c").read_text() == "mine"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ehss_compensator.c"]


def test_a_bad_folder_is_one_line_and_exit_2(tmp_path, capsys):
    (tmp_path / "file").write_text("x")
    for bad in (tmp_path / "missing" / "out", tmp_path / "file"):
        assert main(["target-code", "--out", str(bad)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "Traceback" not in err
    assert not (tmp_path / "missing").exists()


def test_docs_carry_the_integration_note():
    # docs/target.md repeats the note the command writes, section for section
    doc = DOCS.read_text(encoding="utf-8")
    note = target_code_files()["README.md"]
    body = note.split("\n", 2)[2].replace("\n## ", "\n### ")
    assert body in doc
