"""The package's layout: no module reaches into another module's private names.

Every module of ``depthcore`` is parsed with :mod:`ast`. A module may use its
own underscore names freely and the package's helper module ``_checks``
through its public names; it may not import an underscore name from another
``depthcore`` module, read one as an attribute of another ``depthcore`` module
(``optimal._integrate``), nor read, on an object of another module, a private
attribute that only another module defines (``marginals._start``).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "depthcore"


def _module_name(path: Path) -> str:
    """A source's module name below ``depthcore``: ``model``, ``book.paper``, ``book``."""
    parts = path.relative_to(PACKAGE).with_suffix("").parts
    if parts[-1] == "__init__" and len(parts) > 1:
        parts = parts[:-1]
    return ".".join(parts)


#: Every module of the package by its name below ``depthcore``; a subpackage by its own name.
PATHS = {_module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}
MODULES = sorted(PATHS)
#: The package's subpackages (their ``__init__``), where relative imports start from.
SUBPACKAGES = {_module_name(p) for p in PACKAGE.rglob("__init__.py") if p.parent != PACKAGE}


def _package(own: str | None) -> str:
    """The package in which the module ``own`` resolves its relative imports."""
    if own is None or own in SUBPACKAGES:
        return own or ""
    return own.rpartition(".")[0]


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _owner(node: ast.ImportFrom, package: str = "") -> str | None:
    """The depthcore module that an ``import from`` in ``package`` names (``""``: the package)."""
    if node.level >= 1:
        base = package.split(".") if package else []
        base = base[: len(base) - (node.level - 1)]
        return ".".join(base + ([node.module] if node.module else []))
    if node.level == 0 and node.module is not None:
        parts = node.module.split(".")
        if parts[0] == "depthcore":
            return ".".join(parts[1:])
    return None


def defined_private(source: str) -> set[str]:
    """The underscore names a module defines: top-level and class-level names, ``x._a = ...``."""
    names = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            names.add(node.id)
        elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store):
            names.add(node.attr)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
    return {n for n in names if _private(n)}


DEFINED = {m: defined_private(PATHS[m].read_text(encoding="utf-8")) for m in MODULES}


def bound_modules(tree: ast.AST, modules, package: str = "") -> dict[str, str]:
    """The local names bound to ``depthcore`` modules: ``from depthcore import x as y``, ...

    Returns
    -------
    dict mapping each local name to the module (one of ``modules``) it stands for
    """
    bound = {}
    for node in ast.walk(tree):
        owner = _owner(node, package) if isinstance(node, ast.ImportFrom) else None
        if owner is not None:
            for alias in node.names:
                full = f"{owner}.{alias.name}" if owner else alias.name
                if full in modules:
                    bound[alias.asname or alias.name] = full
        elif isinstance(node, ast.Import):
            for alias in node.names:
                parts = alias.name.split(".")
                name = ".".join(parts[1:])
                if parts[0] == "depthcore" and name in modules and alias.asname:
                    bound[alias.asname] = name
    return bound


def taken_names(tree: ast.AST, modules, own: str | None = None):
    """Every name taken from a ``depthcore`` module other than ``own``, imported or read.

    Yields
    ------
    tuple of (line, owner, name, description)
    """
    package = _package(own)
    bound = bound_modules(tree, modules, package)
    for node in ast.walk(tree):
        owner = _owner(node, package) if isinstance(node, ast.ImportFrom) else None
        if owner in modules and owner != own:
            for alias in node.names:
                yield node.lineno, owner, alias.name, f"imports {alias.name} from {owner}"
        elif (
            isinstance(node, ast.Attribute)
            and isinstance(node.value, ast.Name)
            and bound.get(node.value.id, own) != own
        ):
            owner = bound[node.value.id]
            yield node.lineno, owner, node.attr, f"uses {node.value.id}.{node.attr}"


def private_uses(source: str, own: str, defined: dict[str, set[str]] | None = None) -> list[str]:
    """Every use, in ``source`` (the module ``own``), of another module's underscore name.

    ``defined`` maps each module to the underscore names it defines (by default
    the package's, :data:`DEFINED`): an attribute ``obj._a`` read on any object
    counts when ``_a`` is defined by another module and not by ``own``.

    Returns
    -------
    list of str, one ``"line: description"`` per use
    """
    defined = DEFINED if defined is None else defined
    others = set().union(*(names for m, names in defined.items() if m != own))
    mine = defined_private(source)
    tree = ast.parse(source)
    modules = bound_modules(tree, MODULES, _package(own))
    found = [
        f"{line}: {how}" for line, _, name, how in taken_names(tree, MODULES, own) if _private(name)
    ]
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.Attribute)
            and isinstance(node.ctx, ast.Load)
            and _private(node.attr)
            and node.attr in others
            and node.attr not in mine
            and not (isinstance(node.value, ast.Name) and node.value.id in modules)
        ):
            found.append(f"{node.lineno}: reads .{node.attr}, private to another module")
    return sorted(found, key=lambda u: int(u.split(":")[0]))


def test_finds_what_it_looks_for():
    source = (
        "from . import optimal, _checks\n"
        "from .bank import _halving, moments\n"
        "from depthcore.kalman import _joseph\n"
        "x = optimal._integrate(1) + _checks.as_float(2, 'a') + optimal.moments\n"
        "def _own():\n    return _halving\n"
    )
    defined = {"optimal": {"_integrate", "_start"}, "study": set()}
    assert private_uses(source, "study", defined) == [
        "2: imports _halving from bank",
        "3: imports _joseph from kalman",
        "4: uses optimal._integrate",
    ]
    assert private_uses("def g(m):\n    return m._start\n", "study", defined) == [
        "2: reads ._start, private to another module"
    ]
    own = "def g(m):\n    m._start = 1\n    return m._start\n"
    assert private_uses(own, "study", defined) == []
    helper = "from . import _checks\nfrom ._checks import as_float\n"
    assert private_uses(helper, "x", defined) == []


@pytest.mark.parametrize("module", MODULES)
def test_no_module_uses_another_modules_private_names(module):
    source = PATHS[module].read_text(encoding="utf-8")
    assert private_uses(source, module) == []


# --- no re-export facades -------------------------------------------------------------

ROOT = PACKAGE.parent


def defined_names(source: str) -> set[str]:
    """The names a module binds at its top level other than by importing them."""
    return _bound(ast.parse(source).body)


def _bound(statements) -> set[str]:
    names = set()
    for node in statements:
        targets = []
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.Assign):
            targets = node.targets
        elif isinstance(node, (ast.AnnAssign, ast.AugAssign)):
            targets = [node.target]
        elif isinstance(node, ast.If):
            names |= _bound(node.body) | _bound(node.orelse)
        elif isinstance(node, ast.Try):
            names |= _bound(node.body) | _bound(node.orelse) | _bound(node.finalbody)
            for handler in node.handlers:
                names |= _bound(handler.body)
        for t in targets:
            names |= {n.id for n in ast.walk(t) if isinstance(n, ast.Name)}
    return names


DEFINES = {m: defined_names(PATHS[m].read_text(encoding="utf-8")) for m in MODULES}


def borrowed_uses(
    source: str, defines: dict[str, set[str]] | None = None, own: str | None = None
) -> list[str]:
    """Every name taken from a ``depthcore`` module that only imports it from another.

    ``from depthcore.particle import systematic`` and ``particle.systematic``
    both count when :mod:`depthcore.particle` does not define ``systematic``:
    a name is imported from the module that defines it.

    Returns
    -------
    list of str, one ``"line: description"`` per use
    """
    defines = DEFINES if defines is None else defines
    tree = ast.parse(source)
    # a module's modules (``filters.optimal``) are the package's: not counted
    found = [
        f"{line}: {how}"
        for line, owner, name, how in taken_names(tree, defines, own)
        if name not in defines[owner] | set(defines)
        and f"{owner}.{name}" not in defines
        and not name.startswith("__")
    ]
    return sorted(found, key=lambda u: int(u.split(":")[0]))


def code_cells(page: Path) -> str:
    """The Python of a MyST page's code cells, magics left out."""
    cells, inside = [], False
    for line in page.read_text(encoding="utf-8").splitlines():
        if line.startswith("```{code-cell}"):
            inside = True
        elif inside and line.startswith("```"):
            inside = False
        elif inside and not line.startswith((":", "%", "!")):
            cells.append(line)
    return "\n".join(cells)


def test_finds_borrowed_names():
    defines = {"particle": {"run"}, "resampling": {"systematic"}}
    source = (
        "from depthcore import particle\n"
        "from depthcore.particle import run, systematic\n"
        "from depthcore.resampling import systematic as s\n"
        "x = particle.systematic(1) + particle.run(2)\n"
    )
    assert borrowed_uses(source, defines) == [
        "2: imports systematic from particle",
        "4: uses particle.systematic",
    ]


SOURCES = (
    [p for p in sorted(PACKAGE.rglob("*.py")) if p.stem != "__init__"]
    + sorted((ROOT / "tests").glob("*.py"))
    + sorted((ROOT / "benchmarks").glob("*.py"))
    + sorted((ROOT / "book").glob("*.md"))
)


@pytest.mark.parametrize("path", SOURCES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_name_is_imported_from_the_module_that_defines_it(path):
    source = code_cells(path) if path.suffix == ".md" else path.read_text(encoding="utf-8")
    own = _module_name(path) if path.is_relative_to(PACKAGE) else None
    assert borrowed_uses(source, own=own) == []


@pytest.mark.parametrize("module", [m for m in MODULES if m != "__init__" and m not in SUBPACKAGES])
def test_all_lists_only_names_the_module_defines(module):
    tree = ast.parse(PATHS[module].read_text(encoding="utf-8"))
    listed = [
        ast.literal_eval(node.value)
        for node in tree.body
        if isinstance(node, ast.Assign)
        and any(isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets)
    ]
    for names in listed:
        assert set(names) <= DEFINES[module]


# --- the mathematics knows nothing of the book ----------------------------------------

#: The modules outside the book's wing that show its work: the command line draws the
#: paper's figures and prints vectors as the book does, the benchmarks' tables are
#: shown as the book's tables.
BOOK_USERS = {"__main__", "cli_text", "benchmark_tables"}


def imported_modules(source: str, own: str) -> set[str]:
    """The ``depthcore`` modules and packages that the module ``own`` imports from."""
    tree = ast.parse(source)
    package = _package(own)
    found = set(bound_modules(tree, MODULES, package).values())
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and _owner(node, package):
            found.add(_owner(node, package))
    return found


def test_finds_imports_of_the_book():
    source = "from .book import paper\nfrom .book.style import STYLE\nfrom . import model\n"
    assert imported_modules(source, "x") == {"book", "book.paper", "book.style", "model"}
    assert imported_modules("from ..filters import FILTERS\n", "book.style") == {"filters"}


@pytest.mark.parametrize(
    "module", [m for m in MODULES if "." not in m and m not in SUBPACKAGES | BOOK_USERS]
)
def test_no_module_outside_the_book_imports_it(module):
    imported = imported_modules(PATHS[module].read_text(encoding="utf-8"), module)
    assert not [m for m in imported if m == "book" or m.startswith("book.")]
