"""``python -m ehss``: the same as the ``ehss`` command."""

import sys

from ehss.cli import main

sys.exit(main())
