"""Command-line interface of ehss: a thin adapter over the library.

Each subcommand lives in its own module with a ``register(subparsers)`` function that
adds its parser and sets ``func``. Errors raised on purpose (:class:`~ehss.errors.EhssError`)
become one line on stderr and exit code 2 for bad input or parameters, 1 otherwise;
argument errors also exit with 2. Every file argument is checked before the command
runs (:mod:`ehss.cli._outputs`), so no output replaces an input or another file.

Ctrl-C prints one line and exits with 130, also while the libraries are still being
imported; SIGTERM is turned into an exception, so temporary files and folders are
removed on the way out, and exits with 143.
"""

from __future__ import annotations

# Only light modules here: the console script imports this package before main() can
# catch Ctrl-C, so argparse and everything heavier are imported inside main().
import contextlib
import os
import signal
import sys
from collections.abc import Iterator, Sequence

TYPE_CHECKING = False  # typing itself imports re: not here
if TYPE_CHECKING:
    import argparse
    from types import FrameType
    from typing import NoReturn

__all__ = [
    "main",
    "entry",
    "build_parser",
    "EXIT_OK",
    "EXIT_FAILURE",
    "EXIT_BAD_INPUT",
    "EXIT_INTERRUPTED",
    "EXIT_TERMINATED",
]

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 128 + int(signal.SIGINT)
EXIT_TERMINATED = 128 + int(signal.SIGTERM)

# The subcommands in the order `ehss --help` lists them: (name, module ehss.cli._<module>
# that registers it, one-line help). The help lines are here, not in the modules, so
# that listing the commands imports none of them (numpy, scipy, numba take a second).
_COMMANDS = (
    ("params", "params", "print a parameter set with units and its loops' stability (or "
     "retune the loops, or save it as TOML)"),
    ("simulate", "simulate", "simulate a closed-loop test (position, acceleration or force "
     "loop)"),
    ("identify", "identify", "identify an ARMAX-family model from an input/output record "
     "and validate it"),
    ("frf", "frf", "H1 frequency response and coherence of an input/output record"),
    ("order", "order", "order-selection table (validation fit, AIC, FPE, MDL, verdict) over "
     "a grid"),
    ("compensate", "compensate", "compute a checked, compensated drive from an identified "
     "closed-loop model"),
    ("compensate-demo", "compensate", "demonstrate inverse-model compensation on the "
     "simulated rig"),
    ("reproduce", "reproduce", "run the paper's experiments end to end and write a report"),
    ("live", "live", "identify a running rig online (UDP, simulated rig or replay), detect "
     "changes, record, dashboard"),
    ("stream", "stream", "send the simulated rig or a file as UDP datagrams (for ehss live "
     "--udp)"),
    ("target-code", "target", "write the C99 compensator filter and datagram decoder for a "
     "real-time target, with an integration note"),
    ("batch", "batch", "identify every channel of every record of an archive on Dask, "
     "follow the loops' figures, flag odd records"),
    ("montecarlo", "montecarlo", "how the compensation holds across the rig's uncertain "
     "parameters (sampled, on Dask)"),
)


def command_help(name: str) -> str:
    """The one-line help of subcommand ``name``, as ``ehss --help`` lists it."""
    return next(text for command, _, text in _COMMANDS if command == name)


def add_command(sub: argparse._SubParsersAction, name: str, *, description: str,
                epilog: str | None = None) -> argparse.ArgumentParser:
    """Add the parser of subcommand ``name`` with its one-line help (:func:`command_help`)."""
    parser: argparse.ArgumentParser = sub.add_parser(
        name, help=command_help(name), description=description, epilog=epilog)
    return parser


def build_parser(argv: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """The ``ehss`` parser: with every subcommand registered in full, or, for the
    command line ``argv``, only the one it names (the others listed by name and help,
    so that their modules and what they import are not loaded)."""
    import argparse
    import importlib

    class _Parser(argparse.ArgumentParser):
        """ArgumentParser whose errors are one line on stderr and exit code 2."""

        def error(self, message: str) -> None:  # type: ignore[override]
            self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message}\n")

    class _Version(argparse.Action):
        """``--version``: the installed version, looked up only when asked for (the
        package metadata's reader costs tens of milliseconds at every start)."""

        def __init__(self, option_strings: list[str], dest: str) -> None:
            super().__init__(option_strings, dest=argparse.SUPPRESS,
                             default=argparse.SUPPRESS, nargs=0,
                             help="show the version of ehss and exit")

        def __call__(self, parser: argparse.ArgumentParser, *args: object) -> None:
            from ehss import __version__

            print(f"ehss {__version__}")   # on stdout, as argparse's own version action
            parser.exit()

    parser = _Parser(
        prog="ehss",
        description="Electro-hydraulic servo systems: simulate the rig, identify its closed "
        "loops with RELS, validate the models and compensate the drive.",
    )
    parser.add_argument("--version", action=_Version)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    named = None if argv is None else _named_command(argv)
    registered: set[str] = set()
    for name, module_name, text in _COMMANDS:
        if name in registered:
            continue
        if argv is not None and module_name != named:
            sub.add_parser(name, help=text, add_help=False)  # listed, not loaded
            continue
        try:
            module = importlib.import_module(f"ehss.cli._{module_name}")
        except ModuleNotFoundError as exc:
            if exc.name == f"ehss.cli._{module_name}":
                continue  # subcommand not available in this build
            raise
        module.register(sub)
        registered.update(sub.choices)
    return parser


def _named_command(argv: Sequence[str]) -> str | None:
    """The module of the subcommand ``argv`` names (its first word that is not an
    option), or None."""
    word = next((a for a in argv if not a.startswith("-")), None)
    return next((module for name, module, _ in _COMMANDS if name == word), None)


class _Terminated(BaseException):
    """SIGTERM, raised in the main thread so that ``finally`` clauses clean up."""


@contextlib.contextmanager
def _sigterm_as_exception() -> Iterator[None]:
    """Raise :class:`_Terminated` on SIGTERM while the command runs.

    Later SIGTERMs are ignored while the clean-up runs; the previous handler is restored
    on the way out.
    """
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum: int, frame: FrameType | None) -> NoReturn:
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        raise _Terminated

    previous = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _tolerant_streams() -> None:
    """Let stdout and stderr replace what their encoding cannot show.

    A terminal set to latin-1 or ASCII cannot encode the arrows and Greek letters ehss
    prints; the text is still worth reading with a ``?`` in their place, where an
    encoding error would end the command.
    """
    for stream in (sys.stdout, sys.stderr):
        reconfigure = getattr(stream, "reconfigure", None)
        if reconfigure is not None and getattr(stream, "errors", "strict") == "strict":
            with contextlib.suppress(ValueError, OSError):
                reconfigure(errors="replace")


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``ehss`` command line; returns the exit code."""
    command = "ehss"
    _tolerant_streams()
    try:
        with _sigterm_as_exception():
            argv = sys.argv[1:] if argv is None else list(argv)
            parser = build_parser(argv)  # imports the command argv names, and numpy...
            args = parser.parse_args(argv)
            if getattr(args, "func", None) is None:
                parser.print_help(sys.stderr)
                return EXIT_BAD_INPUT
            command = f"ehss {args.command}"
            return _run(command, args)
    except KeyboardInterrupt:
        print(f"{command}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except _Terminated:
        print(f"{command}: terminated", file=sys.stderr)
        return EXIT_TERMINATED


def _run(command: str, args: argparse.Namespace) -> int:
    from ehss.cli._outputs import check_paths
    from ehss.errors import DataError, EhssError, ParameterError

    try:
        check_paths(args)
        code = args.func(args)
    except (DataError, ParameterError) as exc:
        print(f"{command}: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except EhssError as exc:
        print(f"{command}: error: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    except MemoryError:
        print(f"{command}: error: not enough memory for this job (shorten the "
              "record or lower the sample rate)", file=sys.stderr)
        return EXIT_FAILURE
    except OSError as exc:
        return _os_error(command, exc)
    return EXIT_OK if code is None else int(code)


def _os_error(command: str, exc: OSError) -> int:
    """One line for an operating-system error no command turned into its own message.

    A file the command could not open (no permission, a folder where a file was meant)
    is bad input: exit 2, naming the file. Standard output that cannot take what the
    command prints (a closed pipe, as in ``ehss frf ... | head -0``, or a full disk) ends
    the command with exit 1; stdout is pointed at ``os.devnull`` so that the interpreter's
    last flush does not fail again.
    """
    reason = exc.strerror or type(exc).__name__
    if exc.filename is not None:
        name = os.fsdecode(exc.filename).encode("utf-8", "backslashreplace").decode()
        print(f"{command}: error: {name!r}: {reason}", file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):
        pass  # stdout is not a file descriptor (captured): nothing to flush to it
    print(f"{command}: error: cannot write to standard output: {reason}", file=sys.stderr)
    return EXIT_FAILURE


def entry() -> None:  # pragma: no cover - console-script shim
    """The `ehss` console script and `python -m ehss`: run :func:`main` and exit."""
    sys.exit(main())
