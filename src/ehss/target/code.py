"""The C99 files a real-time target builds, and their integration note, as text.

``ehss target-code --out DIR`` writes them out; the files are package data under
``ehss/target/c``.
"""

from __future__ import annotations

from importlib import resources

__all__ = ["TARGET_FILES", "target_code_files"]

#: The files ``ehss target-code`` writes, in order.
TARGET_FILES = ("ehss_compensator.h", "ehss_compensator.c", "README.md")


def target_code_files() -> dict[str, str]:
    """``{file name: text}`` of the C header, the C source and the integration note."""
    folder = resources.files("ehss.target").joinpath("c")
    return {name: folder.joinpath(name).read_text(encoding="utf-8") for name in TARGET_FILES}
