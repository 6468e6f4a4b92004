"""``python -m ehss``: the same as the ``ehss`` command."""

from ehss.cli import entry

if __name__ == "__main__":
    entry()
