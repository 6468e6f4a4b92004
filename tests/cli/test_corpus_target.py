"""Hostile output folders for ``ehss target-code``, run as users run it: a file where
the folder should be, a folder whose parent is missing, files already there (never
replaced), a folder that cannot be written. Each is one line on stderr and exit 2 and
leaves every file as it was.
"""

from __future__ import annotations

import pytest

NAMES = ("ehss_compensator.h", "ehss_compensator.c", "README.md")


def test_onto_an_existing_file(tmp_path, refused):
    (tmp_path / "out").write_text("a file, not a folder")
    refused(["target-code", "--out", "out"], tmp_path, "out")


def test_into_a_missing_parent(tmp_path, refused):
    refused(["target-code", "--out", "none/out"], tmp_path, "none")


@pytest.mark.parametrize("name", NAMES)
def test_a_file_already_there_is_never_replaced(tmp_path, refused, name):
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / name).write_text("the user's own")
    refused(["target-code", "--out", "out"], tmp_path, name)


def test_into_a_read_only_folder(tmp_path, refused, unwritable_folder):
    refused(["target-code", "--out", str(unwritable_folder)], tmp_path,
            str(unwritable_folder))


def test_without_out(tmp_path, refused):
    refused(["target-code"], tmp_path, "--out")


def test_a_good_folder_gets_every_file(tmp_path, ehss_cli):
    run = ehss_cli(["target-code", "--out", "out"], tmp_path)
    assert run.code == 0, run.err
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == sorted(NAMES)
