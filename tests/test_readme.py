"""The README's Python examples run as written and show what the README says they show."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"


def python_blocks(text: str) -> list[str]:
    """Every fenced ```python block of a Markdown text, in order."""
    return re.findall(r"^```python\n(.*?)^```", text, flags=re.MULTILINE | re.DOTALL)


def test_blocks_are_found():
    # an oracle for the extraction itself: two blocks, one with a fence inside a string
    text = "x\n```python\na = 1\n```\n```console\n$ ls\n```\n```python\nb = '```'\n```\n"
    assert python_blocks(text) == ["a = 1\n", "b = '```'\n"]
    assert len(python_blocks(README.read_text(encoding="utf-8"))) >= 2


@pytest.mark.slow
@pytest.mark.parametrize("index", range(len(python_blocks(README.read_text(encoding="utf-8")))))
def test_readme_python_block_runs(index, monkeypatch, capsys):
    """Each block runs on its own from the repository's root, as the README says, with
    warnings as errors (pytest's setting): an example that warns fails here."""
    code = python_blocks(README.read_text(encoding="utf-8"))[index]
    monkeypatch.chdir(ROOT)
    exec(compile(code, f"README.md python block {index + 1}", "exec"), {"__name__": "__main__"})
    printed = capsys.readouterr().out
    if "ehss.compensate(" in code:
        # the first example's promise: a model that meets the acceptance, and a one-shot
        # drive that cuts the tracking error by the factor the README states (about 37×;
        # 30× leaves room for the numeric libraries' versions)
        assert "verdict: meets the acceptance" in printed
        improvement = float(re.search(r"\((\d+)x smaller\)", printed).group(1))
        stated = float(re.search(r"error cut about (\d+)×", README.read_text()).group(1))
        assert improvement >= 30.0 and abs(improvement - stated) <= 0.2 * stated
