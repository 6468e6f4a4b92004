"""The package's static checks run with the suite, so that `make test` (what CI runs) keeps
them: ruff over src, tests and benchmarks (pyflakes, pycodestyle, import order, bugbear,
and every function's McCabe complexity at most 12), and mypy, strict, over the whole
package (pyproject's ``[tool.ruff]`` and ``[tool.mypy]``)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _tool(name: str) -> str:
    path = Path(sys.executable).with_name(name)
    found = str(path) if path.exists() else shutil.which(name)
    if found is None:
        pytest.skip(f"{name} is not installed (pip install -e '.[dev]')")
    return found


def test_ruff_is_clean():
    run = subprocess.run([_tool("ruff"), "check", "--no-cache", "src", "tests", "benchmarks"],
                         cwd=ROOT, capture_output=True, text=True)
    assert run.returncode == 0, run.stdout + run.stderr


def test_mypy_is_clean_over_the_package():
    # nothing cached: a cold run, whose cache would only be thrown away (writing it
    # was a sixth of the run's CPU time)
    run = subprocess.run([_tool("mypy"), "--cache-dir", os.devnull], cwd=ROOT,
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stdout + run.stderr
    modules = len(list((ROOT / "src" / "ehss").rglob("*.py")))
    assert f"no issues found in {modules} source files" in run.stdout, run.stdout
