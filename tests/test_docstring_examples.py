"""The examples in the package's docstrings run as written: each module's ``>>>`` lines
give the output shown (:mod:`doctest`), so that none goes stale."""

from __future__ import annotations

import doctest
import importlib
import pkgutil

import pytest

import ehss

#: Every module of the package that holds an example.
MODULES = sorted(
    info.name for info in pkgutil.walk_packages(ehss.__path__, prefix="ehss.")
    if not info.name.endswith("__main__")
)


def _examples(name: str) -> list[doctest.DocTest]:
    module = importlib.import_module(name)
    return [t for t in doctest.DocTestFinder().find(module, name) if t.examples]


def test_the_package_has_examples_to_run():
    assert sum(len(_examples(name)) for name in MODULES) >= 30


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples_give_the_output_shown(name):
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    report: list[str] = []
    for test in _examples(name):
        runner.run(test, out=report.append)
    result = runner.summarize(verbose=False)
    assert result.failed == 0, "".join(report)
