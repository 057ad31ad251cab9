"""What one study runs, fingerprinted: the code it reaches, the constants and filters it names.

Recommended import: ``from depthbook.provenance import closure``.

A study's record (:mod:`depthbook.provenance.records`) must go stale when, and
only when, something the study computes with changes. :func:`fingerprints`
walks out from the study's function, through the source and not by running
it:

* every depthcore function or class that its code names (a global of its
  module, or an attribute of a module it imports), fingerprinted by its
  syntax tree without docstrings (so that comments, docstrings and layout do
  not count), and in turn every name in that code;
* every constant of a depthcore module that the code names, fingerprinted by
  the statements of its module that bind it (their source, never the value a
  machine computed from it, which may differ in its last bits between
  processors), and in turn every name in them;
* the registry's entries (:data:`depthcore.registry.filters.FILTERS`) that the
  study runs: those named by a string in its arguments, in the constants it
  reads (a tuple of names such as ``NAMES``; ``ALL_NAMES`` names every filter)
  or in its code. The registry itself counts only through these entries, so
  adding a filter leaves a study that does not name it valid, and makes one
  that runs every filter stale;
* every file of the repository that one of those constants names (a data
  file), by its bytes.

What the walk cannot see is a name built at run time (``getattr(module,
name)``): the package's studies do not do that. Third-party code (NumPy,
SciPy) does not count; its versions are stated beside each record.
"""

from __future__ import annotations

import ast
import copy
import dataclasses
import functools
import hashlib
import importlib
import inspect
import os
import sys
import types
from pathlib import Path

from depthbook.provenance import benchmarks

#: The packages whose code a fingerprint covers, the filters' and the book's.
PACKAGES = ("depthcore", "depthbook")
#: The repository, whose files named by a constant are fingerprinted by their bytes.
ROOT = benchmarks.ROOT
#: Where the registry lives, and its name there.
REGISTRY = ("depthcore.registry.filters", "FILTERS")


def _ours(name: str) -> bool:
    return name.partition(".")[0] in PACKAGES


def _digest(text: str) -> str:
    return hashlib.sha256(text.encode()).hexdigest()


@functools.lru_cache(maxsize=512)
def _tree(path: str, mtime_ns: int, size: int) -> ast.Module:
    return ast.parse(Path(path).read_text(encoding="utf-8"), filename=path)


def _module_tree(module: types.ModuleType) -> ast.Module | None:
    path = getattr(module, "__file__", None)
    if not path or not path.endswith(".py") or not os.path.isfile(path):
        return None
    stat = os.stat(path)
    return _tree(path, stat.st_mtime_ns, stat.st_size)


def _definition(tree: ast.Module, qualname: str) -> ast.AST | None:
    """The ``def`` or ``class`` statement of ``qualname`` (its outermost, for a nested one)."""
    parts = qualname.split(".<locals>")[0].split(".")
    body, node = tree.body, None
    for part in parts:
        node = next(
            (
                n
                for n in body
                if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef))
                and n.name == part
            ),
            None,
        )
        if node is None or not isinstance(node, ast.ClassDef):
            break
        body = node.body
    return node


def _bindings(tree: ast.Module, name: str) -> list[ast.AST]:
    """The module-level statements of ``tree`` that bind ``name`` (assignments, imports)."""
    found = []
    for node in tree.body:
        if isinstance(node, (ast.Assign, ast.AnnAssign, ast.AugAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            names = {
                t.id
                for target in targets
                for t in ast.walk(target)
                if isinstance(t, ast.Name) and isinstance(t.ctx, ast.Store)
            }
            subscripted = {
                t.value.id
                for t in targets
                if isinstance(t, ast.Subscript) and isinstance(t.value, ast.Name)
            }
            if name in names | subscripted:
                found.append(node)
        elif isinstance(node, ast.ImportFrom) and any(
            (alias.asname or alias.name) == name for alias in node.names
        ):
            found.append(node)
    return found


def _names(node: ast.AST) -> tuple[list[list[str]], list[str]]:
    """The dotted names that ``node``'s code reads (``a``, ``a.b.c``) and its string constants."""
    chains, strings = [], []
    for inner in ast.walk(node):
        if isinstance(inner, ast.Constant) and isinstance(inner.value, str):
            strings.append(inner.value)
        if isinstance(inner, ast.Name) and isinstance(inner.ctx, ast.Load):
            chains.append([inner.id])
        elif isinstance(inner, ast.Attribute):
            parts, value = [inner.attr], inner.value
            while isinstance(value, ast.Attribute):
                parts.append(value.attr)
                value = value.value
            if isinstance(value, ast.Name):
                chains.append([value.id, *reversed(parts)])
    return chains, strings


#: :func:`_read` of each statement met, by identity (the parsed trees are cached per file version).
_READ: dict[int, tuple[ast.AST, tuple]] = {}


def _read(node: ast.AST) -> tuple[str, list[list[str]], list[str]]:
    """The fingerprint of a statement without its docstrings, and :func:`_names` of it."""
    kept = _READ.get(id(node))
    if kept is None or kept[0] is not node:
        bare = benchmarks.drop_docstrings(copy.deepcopy(node))
        kept = (node, (_digest(ast.dump(bare)), *_names(bare)))
        _READ[id(node)] = kept
    return kept[1]


def _strings(value, seen=None) -> set[str]:
    """Every string inside ``value`` (containers, dataclasses and named tuples walked)."""
    seen = set() if seen is None else seen
    if isinstance(value, str):
        return {value}
    if id(value) in seen or isinstance(value, (types.ModuleType, type, types.FunctionType)):
        return set()
    seen.add(id(value))
    if isinstance(value, dict):
        items = [*value.keys(), *value.values()]
    elif isinstance(value, (list, tuple, set, frozenset)):
        items = list(value)
    elif dataclasses.is_dataclass(value):
        items = [getattr(value, f.name) for f in dataclasses.fields(value)]
    else:
        return set()
    return set().union(*(_strings(v, seen) for v in items)) if items else set()


class _Walk:
    """The fingerprints reached from some functions and arguments (:func:`fingerprints`)."""

    def __init__(self):
        self.prints: dict[str, str] = {}
        self.strings: set[str] = set()
        module = importlib.import_module(REGISTRY[0])
        self.registry = getattr(module, REGISTRY[1])
        self.registry_tree = _module_tree(module)

    def code(self, obj) -> bool:
        """A depthcore function or class, and what its code names; False if its ``def`` is not
        found (a lambda, a function made by another), which the caller then fingerprints by
        the statement that binds it."""
        obj = inspect.unwrap(obj)
        module = sys.modules.get(getattr(obj, "__module__", ""))
        qualname = getattr(obj, "__qualname__", "").split(".<locals>")[0]
        tree = _module_tree(module) if module is not None else None
        node = _definition(tree, qualname) if tree is not None else None
        if node is None:
            return False
        key = f"code {module.__name__}:{qualname}"
        if key not in self.prints:
            self.prints[key], chains, strings = _read(node)
            self.follow(chains, strings, module)
        return True

    def names(self, node: ast.AST, module: types.ModuleType) -> None:
        self.follow(*_read(node)[1:], module)

    def follow(self, chains, strings, module: types.ModuleType) -> None:
        self.strings.update(strings)
        for chain in chains:
            self.name(chain, module)

    def name(self, chain: list[str], module: types.ModuleType) -> None:
        """Resolve a dotted name read in ``module`` and walk what it is."""
        if chain[0] not in vars(module):
            return
        obj, owner, attr = vars(module)[chain[0]], module, chain[0]
        for part in chain[1:]:
            if not isinstance(obj, types.ModuleType) or not hasattr(obj, part):
                break
            owner, attr, obj = obj, part, getattr(obj, part)
        self.object(obj, owner, attr)

    def object(self, obj, owner: types.ModuleType, attr: str) -> None:
        if obj is self.registry or isinstance(obj, types.ModuleType):
            return
        target = inspect.unwrap(obj) if callable(obj) else obj
        if isinstance(target, (types.FunctionType, type)):
            if not _ours(getattr(target, "__module__", "") or "") or self.code(target):
                return
        if _ours(owner.__name__):
            self.constant(owner, attr, obj)

    def constant(self, module: types.ModuleType, name: str, value) -> None:
        """A constant of a depthcore module: the statements that bind it, and its strings."""
        key = f"constant {module.__name__}:{name}"
        if key in self.prints:
            return
        tree = _module_tree(module)
        statements = _bindings(tree, name) if tree is not None else []
        self.prints[key] = _digest("\n".join(_read(s)[0] for s in statements))
        self.strings |= _strings(value)
        self.file(value)
        for statement in statements:
            if isinstance(statement, ast.ImportFrom):
                self.imported(statement, module, name)
            else:
                self.names(statement, module)

    def imported(self, statement: ast.ImportFrom, module: types.ModuleType, name: str) -> None:
        alias = next(a for a in statement.names if (a.asname or a.name) == name)
        package = module.__name__ if hasattr(module, "__path__") else module.__package__
        source = (
            importlib.util.resolve_name("." * statement.level + (statement.module or ""), package)
            if statement.level
            else statement.module
        )
        if source and _ours(source) and source in sys.modules:
            origin = sys.modules[source]
            if alias.name in vars(origin):
                self.object(vars(origin)[alias.name], origin, alias.name)

    def file(self, value) -> None:
        """A file of the repository that ``value`` names, by its bytes."""
        if not isinstance(value, (str, os.PathLike)) or isinstance(value, str):
            return
        path = Path(value)
        if path.is_file() and path.resolve().is_relative_to(ROOT):
            relative = path.resolve().relative_to(ROOT).as_posix()
            self.prints[f"file {relative}"] = hashlib.sha256(path.read_bytes()).hexdigest()

    def filters(self) -> None:
        """The registry's entries named so far, until no new name turns up."""
        done: set[str] = set()
        while todo := sorted((self.strings & set(self.registry)) - done):
            for name in todo:
                done.add(name)
                self.entry(name)

    def entry(self, name: str) -> None:
        """A registry entry: the source of its ``Filter(...)`` and what that names."""
        module = sys.modules[REGISTRY[0]]
        node = _entry_source(self.registry_tree, name)
        if node is None:  # registered at run time, outside the package's source
            entry = self.registry[name]
            self.prints[f"filter {name}"] = _digest(repr(sorted(_strings(entry))))
            for field in dataclasses.fields(entry):
                value = getattr(entry, field.name)
                if callable(value) and _ours(getattr(value, "__module__", "") or ""):
                    self.code(value)
            return
        self.prints[f"filter {name}"] = _read(node)[0]
        self.names(node, module)


def _entry_source(tree: ast.Module | None, name: str) -> ast.AST | None:
    """The expression that makes registry entry ``name``: its ``Filter(name, ...)`` call in the
    statements that bind ``FILTERS``, or the value of ``FILTERS[name] = ...``."""
    if tree is None:
        return None
    for statement in _bindings(tree, REGISTRY[1]):
        for target in getattr(statement, "targets", []):
            if (
                isinstance(target, ast.Subscript)
                and isinstance(target.slice, ast.Constant)
                and target.slice.value == name
            ):
                return statement.value
        for node in ast.walk(statement):
            if (
                isinstance(node, ast.Call)
                and node.args
                and isinstance(node.args[0], ast.Constant)
                and node.args[0].value == name
            ):
                return node
    return None


def fingerprints(function, args=(), kwargs=None) -> dict[str, str]:
    """The fingerprints of what ``function(*args, **kwargs)`` runs (the module docstring).

    Parameters
    ----------
    function : callable
        One of depthcore's functions.
    args, kwargs
        The call's arguments: the registry names among their strings count.

    Returns
    -------
    dict of str to str
        Sorted; keys ``"code module:qualname"``, ``"constant module:NAME"``,
        ``"filter NAME"`` and ``"file path"``, each mapped to 64 hexadecimal
        digits.

    Raises
    ------
    ValueError
        When ``function`` is not one of depthcore's functions.
    """
    target = inspect.unwrap(function) if callable(function) else None
    if not isinstance(target, types.FunctionType) or not _ours(target.__module__):
        raise ValueError(f"function must be one of depthcore's functions, got {function!r}")
    walk = _Walk()
    walk.strings |= _strings(list(args)) | _strings(dict(kwargs or {}))
    walk.code(target)
    walk.filters()
    return dict(sorted(walk.prints.items()))


def changed(recorded: dict, current: dict) -> list[str]:
    """The keys whose fingerprint differs between two :func:`fingerprints`, gone or new included."""
    return sorted(k for k in recorded.keys() | current.keys() if recorded.get(k) != current.get(k))
