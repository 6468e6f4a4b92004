"""Command-line flags made from the library's settings objects, and the objects made back.

A settings object of the library (:class:`ehss.workflow.Preparation`,
:class:`ehss.workflow.Estimation`, :class:`ehss.compensation.UpdateOptions`...) declares
each field once with :func:`ehss.workflow.options.option`: its default, its check, and for
the settings a command offers its flag, help, type and choices. :func:`add_options` adds
those flags to a parser; :func:`build_options` makes the object from the parsed
arguments, passing each value through the field's own check under the flag's name, so
that a bad value is one line naming the flag as it was typed (``--nperseg 4 must be an
integer in [8, inf)``) and exit 2, like every other argument error of the command line.
"""

from __future__ import annotations

import argparse
import dataclasses
from collections.abc import Collection, Mapping
from typing import Any, TypeVar

from ehss.errors import ParameterError

__all__ = ["add_options", "build_options", "option_dest"]

T = TypeVar("T")


def _cli_fields(kind: type, only: Collection[str] | None) -> list[dataclasses.Field]:
    return [f for f in dataclasses.fields(kind) if "cli" in f.metadata
            and (only is None or f.name in only)]


def option_dest(flag: str) -> str:
    """The attribute of the parsed arguments that holds a flag's value (``--frf-method``:
    ``frf_method``)."""
    return flag.lstrip("-").replace("-", "_")


def add_options(parser: argparse._ActionsContainer, kind: type, *,
                only: Collection[str] | None = None,
                help: Mapping[str, str] | None = None) -> None:
    """Add the flags of settings object ``kind`` (its fields that declare one) to
    ``parser``.

    Parameters
    ----------
    parser : argparse.ArgumentParser or argument group
    kind : type
        A settings dataclass declared with :func:`ehss.workflow.options.option`.
    only : collection of str, optional
        The fields to offer (default: every field with a flag).
    help : mapping of str to str, optional
        A command's own help for some fields, by field name.
    """
    for f in _cli_fields(kind, only):
        cli = dict(f.metadata["cli"])
        flag, text = cli.pop("flag"), cli.pop("help")
        cli.pop("parse", None)
        default = cli.pop("cli_default", f.default)
        parser.add_argument(flag, default=default, help=(help or {}).get(f.name, text),
                            **cli)


def build_options(args: argparse.Namespace, kind: type[T], *,
                  only: Collection[str] | None = None, **given: Any) -> T:
    """The settings object ``kind`` from the flags :func:`add_options` added.

    A flag not given (None) leaves its field at the default; ``given`` sets fields the
    command knows otherwise (a separate validation record).

    Raises
    ------
    ParameterError
        For a value the field's check refuses, named by its flag (``--holdout 1.5 must be
        in (0, 1)``).
    """
    values: dict[str, Any] = {}
    for f in _cli_fields(kind, only):
        cli = f.metadata["cli"]
        flag = cli["flag"]
        value = getattr(args, option_dest(flag))
        if value is None:
            continue
        if "parse" in cli:
            value = cli["parse"](value, flag)
        if isinstance(value, list):
            value = tuple(value)
        values[f.name] = _checked(f, value, flag)
    return kind(**{**values, **given})


def _checked(f: dataclasses.Field, value: Any, flag: str) -> Any:
    """``value`` through the field's check, a refusal named by the flag as typed."""
    try:
        return f.metadata["check"](value, flag)
    except (TypeError, ParameterError) as exc:
        text = str(exc)
        if text.startswith(f"{flag}="):
            text = f"{flag} {text[len(flag) + 1:]}"
        raise ParameterError(text) from None
