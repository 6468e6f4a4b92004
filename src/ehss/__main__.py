"""``python -m ehss``: the same as the ``ehss`` command."""

from ehss.cli import entry

entry()
