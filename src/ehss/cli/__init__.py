"""Command-line interface of ehss: a thin adapter over the library.

Each subcommand lives in its own module with a ``register(subparsers)`` function that
adds its parser and sets ``func``. Errors raised on purpose (:class:`~ehss.errors.EhssError`)
become one line on stderr and exit code 2 for bad input or parameters, 1 otherwise;
argument errors also exit with 2.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from ehss.errors import DataError, EhssError, ParameterError

__all__ = ["main", "build_parser", "EXIT_OK", "EXIT_FAILURE", "EXIT_BAD_INPUT"]

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_BAD_INPUT = 2

# Subcommand modules, in the order they are listed by `ehss --help`.
_COMMANDS = (
    "params",
    "simulate",
    "identify",
    "frf",
    "order",
    "compensate",
    "reproduce",
    "live",
    "stream",
)


class _Parser(argparse.ArgumentParser):
    """ArgumentParser whose errors are one line on stderr and exit code 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    """The ``ehss`` parser with every available subcommand registered."""
    from ehss import __version__

    parser = _Parser(
        prog="ehss",
        description="Electro-hydraulic servo systems: simulate the rig, identify its closed "
        "loops with RELS, validate the models and compensate the drive.",
    )
    parser.add_argument("--version", action="version", version=f"ehss {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for name in _COMMANDS:
        try:
            module = importlib.import_module(f"ehss.cli._{name}")
        except ModuleNotFoundError as exc:
            if exc.name == f"ehss.cli._{name}":
                continue  # subcommand not available in this build
            raise
        module.register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``ehss`` command line; returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "func", None) is None:
        parser.print_help(sys.stderr)
        return EXIT_BAD_INPUT
    try:
        code = args.func(args)
    except (DataError, ParameterError) as exc:
        print(f"ehss {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except EhssError as exc:
        print(f"ehss {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    except MemoryError:
        print(f"ehss {args.command}: error: not enough memory for this job (shorten the "
              "record or lower the sample rate)", file=sys.stderr)
        return EXIT_FAILURE
    except KeyboardInterrupt:
        print(f"ehss {args.command}: interrupted", file=sys.stderr)
        return 130
    return EXIT_OK if code is None else int(code)


def _entry() -> None:  # pragma: no cover - console-script shim
    sys.exit(main())
