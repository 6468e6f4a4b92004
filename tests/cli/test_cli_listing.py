"""``ehss --help`` lists every command without loading any of them."""

from __future__ import annotations

import subprocess
import sys

from ehss.cli import _COMMANDS, build_parser


def test_the_listing_loads_no_command_module_and_nothing_heavy():
    code = ("import sys\n"
            "from ehss.cli import main\n"
            "try:\n"
            "    main(['--help'])\n"
            "except SystemExit as exc:\n"
            "    assert exc.code == 0, exc.code\n"
            "loaded = [m for m in sys.modules if m.startswith('ehss.cli._') or\n"
            "          m.split('.')[0] in ('numpy', 'scipy', 'numba', 'matplotlib')]\n"
            "print('loaded:', ','.join(sorted(loaded)))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.rstrip("\n").splitlines()
    assert out[-1] == "loaded: "
    listing = "\n".join(out[:-1])
    for name, _, text in _COMMANDS:
        assert name in listing and text.split()[0] in listing


def test_a_named_command_is_registered_in_full_and_the_others_by_name():
    parser = build_parser(["order", "run.csv", "--input", "u", "--output", "y"])
    sub = next(a for a in parser._actions if a.dest == "command")  # argparse's own store
    assert list(sub.choices) == [name for name, _, _ in _COMMANDS]
    order_options = {o for a in sub.choices["order"]._actions for o in a.option_strings}
    assert {"--na", "--delay", "--criterion"} <= order_options
    assert not [a for a in sub.choices["identify"]._actions if a.option_strings]


def test_every_command_is_registered_in_full_without_a_command_line():
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    for name, _, _ in _COMMANDS:
        assert any(a.option_strings for a in sub.choices[name]._actions), name
