"""``ehss.__main__`` runs the command line only as the main module: importing it (as
documentation tools and test collectors do) runs nothing and does not exit."""

from __future__ import annotations

import importlib
import sys


def test_importing_the_main_module_runs_no_command(monkeypatch, capsys):
    monkeypatch.setattr(sys, "argv", ["ehss", "--version"])
    sys.modules.pop("ehss.__main__", None)
    importlib.import_module("ehss.__main__")  # would exit 0 after printing the version
    assert capsys.readouterr().out == ""


def test_run_as_the_main_module_it_is_the_command(tmp_path, ehss_cli):
    run = ehss_cli(["--version"], tmp_path)
    assert (run.code, run.out.split()[0]) == (0, "ehss")
