"""The package's floors: no module imports a higher floor or another package's private names;
and arguments are checked in one place.

Every module under ``src/ehss`` is parsed (no import is executed) and each of its
``import`` / ``from ... import`` statements, wherever it stands (module level or inside
a function), is resolved to the ehss module and name it reaches.

Floors, lowest first; a module may import its own floor and any floor below. The
shared helpers (``errors`` and the private ``_checks``, ``_files``, ``_provenance`` of
the ``ehss`` package itself) are the ground floor.

Argument checks go through ``ehss._checks``, so that one mistake is reported with one
error type and one message wherever it is made: no other module may test a type inline
as ``isinstance(x, bool) or not isinstance(x, ...)``.
"""

from __future__ import annotations

import ast
from dataclasses import dataclass, replace
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
PACKAGE = SRC / "ehss"

#: Each entry is one floor: the top-level modules or packages of ehss on it.
FLOORS: tuple[tuple[str, ...], ...] = (
    ("errors", "_checks", "_files", "_provenance", "_settle"),
    ("params",),
    ("linear",),
    ("plant",),
    ("control",),
    ("simulation",),
    ("signals",),
    ("io",),
    ("identification",),
    ("_warm",),  # compiles the simulator's and the estimators' kernels ahead of use
    ("frequency",),
    ("preprocess",),
    ("validation",),
    ("workflow",),
    ("plots",),
    ("compensation",),
    ("target",),  # the compensator filter a real-time target runs, and its datagram
    ("experiments",),
    ("report",),
    ("campaign",),  # campaigns over many records or simulated rigs, on Dask
    ("ehss",),  # the package's __init__: re-exports the library
    ("live",),  # online identification of a running rig, built on the public library
    ("cli",),
    ("__main__",),
)

# Known exceptions, each to be removed when the import it names is gone. Entries are
# (importing module, imported module or name).
ALLOWED_PRIVATE: frozenset[tuple[str, str]] = frozenset()
ALLOWED_UPWARD: frozenset[tuple[str, str]] = frozenset()

#: The one module that may test types inline: the checks everything else calls.
CHECKS_MODULE = "_checks.py"

# Modules (paths under src/ehss) allowed to test types inline instead of calling
# ehss._checks, named by file: none. An entry would leave the list as soon as its module
# is converted (test_inline_check_allow_list_holds_only_modules_that_still_need_it).
ALLOWED_INLINE_CHECKS: frozenset[str] = frozenset()


@dataclass(frozen=True)
class Import:
    importer: str  # dotted module name, e.g. "ehss.report.render"
    target: str  # dotted name reached, e.g. "ehss.report.figures.step_figure"
    line: int
    target_unit: str = ""  # top-level module or package reached, e.g. "report"


def module_name(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def is_package(path: Path) -> bool:
    return path.name == "__init__.py"


def imports_of(source: str, importer: str, *, package: bool) -> list[Import]:
    """Every ehss name that ``source`` (the module ``importer``) imports."""
    out = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            out += [Import(importer, a.name, node.lineno) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative: resolve against the importer's package
                anchor = importer.split(".")
                if not package:
                    anchor = anchor[:-1]
                anchor = anchor[: len(anchor) - (node.level - 1)]
                base = ".".join(anchor + ([base] if base else []))
            out += [Import(importer, f"{base}.{a.name}", node.lineno) for a in node.names]
    return [i for i in out if i.target == "ehss" or i.target.startswith("ehss.")]


def unit(name: str, modules: set[str]) -> str:
    """The top-level module or package of ehss that ``name`` belongs to.

    ``ehss.report.render`` → ``report``; a name defined in the package's ``__init__``
    (``ehss.__version__``, ``ehss.simulate``) → ``ehss``.
    """
    parts = name.split(".")
    if len(parts) > 1 and f"ehss.{parts[1]}" in modules:
        return parts[1]
    return "ehss"


def floor(u: str) -> int:
    for level, units in enumerate(FLOORS):
        if u in units:
            return level
    raise AssertionError(f"top-level {u!r} is on no floor; add it to FLOORS")


def private_owner(imp: Import) -> str | None:
    """The package whose private name or module ``imp`` reaches, or None if public.

    ``ehss.control._kernels`` and ``ehss.control.discrete._helper`` → ``ehss.control``:
    only modules under it may import them; a top-level module is its own package here
    (``ehss.frequency._check_band`` → ``ehss.frequency``). The private helpers of the
    ``ehss`` package itself (``ehss._files``) are shared by all of ehss.
    """
    parts = imp.target.split(".")
    private = [
        p for p in parts[1:] if p.startswith("_") and not (p.startswith("__") and p.endswith("__"))
    ]
    if not private:
        return None
    return "ehss" if parts[1].startswith("_") else f"ehss.{imp.target_unit}"


def private_violation(imp: Import) -> bool:
    owner = private_owner(imp)
    if owner is None or owner == "ehss":
        return False
    return not (imp.importer == owner or imp.importer.startswith(owner + "."))


def upward_violation(imp: Import) -> bool:
    return floor(imp.target_unit) > floor(imp.importer.split(".")[1] if "." in imp.importer
                                          else "ehss")


def allowed(imp: Import, allow: frozenset[tuple[str, str]]) -> bool:
    return any(
        imp.importer == who and (imp.target == what or imp.target.startswith(what + "."))
        for who, what in allow
    )


def all_imports(root: Path = SRC) -> list[Import]:
    """Every ehss import of every module under ``root / "ehss"``."""
    paths = sorted((root / "ehss").rglob("*.py"))
    modules = {module_name(p, root) for p in paths}
    out = []
    for path in paths:
        name = module_name(path, root)
        for imp in imports_of(path.read_text(encoding="utf-8"), name, package=is_package(path)):
            out.append(replace(imp, target_unit=unit(imp.target, modules)))
    return out


def _describe(imps: list[Import]) -> str:
    return "\n".join(f"  {i.importer} (line {i.line}) imports {i.target}" for i in imps)


# --------------------------------------------------------------------------- the tree
@pytest.fixture(scope="module")
def imports() -> list[Import]:
    found = all_imports()
    assert len(found) > 100  # the walk did find the package's imports
    return found


def test_every_top_level_module_is_on_a_floor():
    names = {p.stem for p in PACKAGE.glob("*.py")} | {
        p.name for p in PACKAGE.iterdir() if (p / "__init__.py").is_file()
    }
    names = {"ehss" if n == "__init__" else n for n in names}
    on_floors = {u for units in FLOORS for u in units}
    assert names - on_floors == set(), "modules on no floor"


def test_no_private_imports_across_packages(imports):
    bad = [i for i in imports if private_violation(i) and not allowed(i, ALLOWED_PRIVATE)]
    assert not bad, "private names imported from outside their package:\n" + _describe(bad)


def test_no_floor_imports_a_higher_one(imports):
    bad = [i for i in imports if upward_violation(i) and not allowed(i, ALLOWED_UPWARD)]
    assert not bad, "imports of a higher floor:\n" + _describe(bad)


@pytest.mark.parametrize("allow", [ALLOWED_PRIVATE, ALLOWED_UPWARD])
def test_allow_lists_hold_only_imports_that_exist(imports, allow):
    # An exception whose import was removed must leave the list, so that it cannot
    # quietly cover a new one.
    found = {(i.importer, i.target) for i in imports}
    stale = [
        (who, what) for who, what in allow
        if not any(w == who and (t == what or t.startswith(what + ".")) for w, t in found)
    ]
    assert not stale, f"allow-list entries with no such import: {stale}"


# --------------------------------------------------------------------- inline type checks
def _is_isinstance(node: ast.AST, *, of_bool: bool = False) -> bool:
    """``node`` is ``isinstance(x, kinds)`` (with ``bool`` or ``np.bool_`` among the
    kinds when ``of_bool``)."""
    if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
            and node.func.id == "isinstance" and len(node.args) == 2):
        return False
    if not of_bool:
        return True
    kinds = node.args[1].elts if isinstance(node.args[1], ast.Tuple) else [node.args[1]]
    return any((isinstance(k, ast.Name) and k.id == "bool")
               or (isinstance(k, ast.Attribute) and k.attr == "bool_") for k in kinds)


def inline_type_checks(source: str) -> list[int]:
    """Lines of ``source`` holding ``isinstance(x, bool) or not isinstance(x, ...)``."""
    lines = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.BoolOp) and isinstance(node.op, ast.Or):
            pairs = zip(node.values[:-1], node.values[1:], strict=True)
            if any(_is_isinstance(a, of_bool=True) and isinstance(b, ast.UnaryOp)
                   and isinstance(b.op, ast.Not) and _is_isinstance(b.operand)
                   for a, b in pairs):
                lines.append(node.lineno)
    return lines


def modules_with_inline_checks(package: Path = PACKAGE) -> dict[str, list[int]]:
    """Each module under ``package`` (path relative to it) with its inline type checks."""
    found = {}
    for path in sorted(package.rglob("*.py")):
        lines = inline_type_checks(path.read_text(encoding="utf-8"))
        if lines:
            found[path.relative_to(package).as_posix()] = lines
    return found


def test_types_are_checked_only_in_the_checks_module():
    found = modules_with_inline_checks()
    bad = {f: lines for f, lines in found.items()
           if f != CHECKS_MODULE and f not in ALLOWED_INLINE_CHECKS}
    assert not bad, ("inline type checks; call ehss._checks (check_int, check_real, "
                     f"check_fs, check_band...) instead: {bad}")
    assert CHECKS_MODULE in found  # the walk does see the pattern where it belongs


def test_inline_check_allow_list_holds_only_modules_that_still_need_it():
    # A module converted to ehss._checks must leave the list, so that the list cannot
    # quietly cover a new inline check.
    found = modules_with_inline_checks()
    stale = sorted(f for f in ALLOWED_INLINE_CHECKS if f not in found)
    assert not stale, f"allow-list entries with no inline type check: {stale}"


def test_inline_check_finder():
    source = (
        "import numpy as np\n"
        "def f(n, x, k):\n"
        "    if isinstance(n, bool) or not isinstance(n, int):\n"
        "        raise TypeError(n)\n"
        "    if (k < 0 or isinstance(x, (bool, np.bool_))\n"
        "            or not isinstance(x, (int, float))):\n"
        "        raise TypeError(x)\n"
        "    if isinstance(k, bool) and not isinstance(k, int):\n"  # not the pattern
        "        pass\n"
        "    return isinstance(n, str) or not isinstance(x, int)\n"  # no bool: not it
    )
    assert inline_type_checks(source) == [3, 5]


# --------------------------------------------------------------------------- the checker
def _synthetic(tmp_path: Path, files: dict[str, str]) -> list[Import]:
    for rel, text in files.items():
        path = tmp_path / "ehss" / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
    return all_imports(tmp_path)


def test_checker_catches_a_private_import_across_packages(tmp_path):
    imps = _synthetic(tmp_path, {
        "__init__.py": "",
        "control/__init__.py": "",
        "control/_kernels.py": "X = 1\n",
        "control/discrete.py": "from ehss.control import _kernels\n",
        "simulation/__init__.py": "",
        "simulation/core.py": "def f():\n    from ehss.control._kernels import X\n",
        "frequency.py": "def _check_band(): pass\n",
        "validation.py": "from ehss.frequency import _check_band\n",
        "report/__init__.py": "",
        "report/render.py": "from ehss._files import atomic_path\nfrom . import _inner\n",
    })
    bad = {(i.importer, i.target) for i in imps if private_violation(i)}
    assert bad == {
        ("ehss.simulation.core", "ehss.control._kernels.X"),
        ("ehss.validation", "ehss.frequency._check_band"),
    }


def test_checker_catches_an_upward_import(tmp_path):
    imps = _synthetic(tmp_path, {
        "__init__.py": "",
        "errors.py": "",
        "params.py": "import ehss.errors\n",
        "plant/__init__.py": "",
        "plant/model.py": "from ehss.params import RigParams\nfrom ehss import signals\n",
        "identification/__init__.py": "",
        "identification/known.py": "from ..control.discrete import generator_zoh\n",
        "identification/model.py": "class ArmaxModel: pass\n",
        "control/__init__.py": "",
        "control/discrete.py": "def generator_zoh(): pass\n",
        "control/known.py": "from ..identification.model import ArmaxModel\n",
        "signals.py": "",
        "cli.py": "from ehss import __version__\nfrom ehss.report import render\n",
        "report/__init__.py": "",
        "report/render.py": "",
    })
    bad = {(i.importer, i.target) for i in imps if upward_violation(i)}
    assert bad == {
        ("ehss.plant.model", "ehss.signals"),
        ("ehss.control.known", "ehss.identification.model.ArmaxModel"),
    }


def test_relative_imports_resolve_against_the_package():
    imps = imports_of("from . import a\nfrom .. import b\nfrom .c import d\n",
                      "ehss.report", package=True)
    assert [i.target for i in imps] == ["ehss.report.a", "ehss.b", "ehss.report.c.d"]
    imps = imports_of("from . import a\nfrom ..x import y\n", "ehss.report.render",
                      package=False)
    assert [i.target for i in imps] == ["ehss.report.a", "ehss.x.y"]
