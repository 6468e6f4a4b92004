"""``ehss target-code``: write the C99 compensator filter and datagram decoder that a
real-time target builds, with their integration note."""

from __future__ import annotations

import argparse

from ehss.cli import add_command
from ehss.cli._outputs import OutputFolder

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    p = add_command(
        sub, "target-code",
        description="Write ehss_compensator.h, ehss_compensator.c (the filter a real-time "
        "target runs and the decoder of the datagram that carries a compensator to it, "
        "portable C99) and README.md (how a Simulink Real-Time or dSPACE S-function or a "
        "Linux real-time loop includes them) into --out. Files already there are never "
        "replaced.",
    )
    p.add_argument("--out", required=True, metavar="DIR", type=OutputFolder,
                   help="folder to write into (made if missing; its parent must exist)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from ehss._files import atomic_path
    from ehss.errors import DataError
    from ehss.target.code import target_code_files

    out = Path(args.out)
    files = target_code_files()
    there = [name for name in files if (out / name).exists() or (out / name).is_symlink()]
    if there:
        raise DataError(f"{str(out / there[0])!r} exists; ehss target-code never replaces "
                        "a file: choose another --out folder or remove the old files")
    out.mkdir(exist_ok=True)
    for name, text in files.items():
        with atomic_path(out / name) as tmp:
            tmp.write_text(text, encoding="utf-8")
    print(f"wrote {', '.join(files)} into {str(out)!r}")
    return 0
