"""The scenebot code each command runs, computed from the imports (standard library only).

``rules/common.smk`` gives every rule, as its ``code`` input, the files that
``python -m scenebot <command>`` runs for it (:func:`command_files`): a change in any of
them re-runs the rule, and a change elsewhere does not. The Snakefile is parsed on every
``snakemake`` call: this reads the source with :mod:`ast` and imports nothing.

The imports of a module (:func:`module_imports`):

* every ``import`` and ``from ... import`` statement, at any depth: inside functions (the
  stages import their heavy libraries where they use them) as well as at the top;
  ``from p import name`` imports the module ``p.name`` when there is one, else ``p``;
* names of scenebot modules written as strings (``importlib.import_module`` of the table
  of built-in scenes). A package with a module ``__getattr__`` (a lazy re-export, see
  :mod:`scenebot._lazy`) keeps its strings apart: ``from p import name`` brings them in
  when ``name`` is not bound in ``p/__init__.py`` itself;
* not: imports under ``if TYPE_CHECKING:`` (never run), logger names
  (``logging.getLogger("scenebot.x")``).

Importing ``a.b.c`` also runs the top level of ``a/__init__.py`` and ``a/b/__init__.py``
(not their functions): :func:`closure` follows a package reached that way through its
module-level imports only.

A command (:func:`command_entry`) starts in ``scenebot/__main__.py`` and ``scenebot/cli.py``:
what every command runs there (the module level, ``build_parser``, ``main`` and the CLI
modules they add parsers from), and of ``cmd_<command>`` alone its own imports and those of
the CLI functions it calls. The other commands' imports are not followed.
"""

from __future__ import annotations

import ast
import functools
import hashlib
import json
import os
import re
from collections.abc import Iterable
from pathlib import Path
from typing import NamedTuple

ROOT = Path(__file__).resolve().parent
"""The package read by default (``root`` of every function: a package folder)."""
ALWAYS_RUN = ("main", "build_parser")
"""Functions of a CLI module that run for every command."""


@functools.cache
def modules(root: Path = ROOT) -> dict[str, Path]:
    """Every module of the package: dotted name -> file (a package's is its ``__init__``)."""
    out = {}
    for path in sorted(root.rglob("*.py")):
        parts = path.relative_to(root).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join((root.name, *parts))] = path
    return out


@functools.cache
def _tree(path: Path) -> ast.Module:
    return ast.parse(path.read_text(encoding="utf-8"), filename=str(path))


class _Raw(NamedTuple):
    """What a part of a module names: modules imported, modules written as strings, and
    ``(package, name)`` of each ``from package import name`` that is not a module."""

    imported: frozenset
    strings: frozenset
    taken: frozenset


def _collect(name: str, nodes: Iterable[ast.stmt], root: Path, functions: bool) -> _Raw:
    """The imports in the statements ``nodes`` of module ``name`` (in function bodies too if
    ``functions``). Statements only are walked (an import is a statement); the strings are
    found in the source text of the same lines."""
    mods = modules(root)
    imported, strings, taken = set(), set(), set()
    spans, skipped = [], []  # line spans walked, and function bodies left out
    for node in nodes:
        spans.append((node.lineno, node.end_lineno))
        for stmt, in_function in _statements([node]):
            if in_function and not functions:
                if isinstance(stmt, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    skipped.append((stmt.lineno, stmt.end_lineno))
                continue
            if isinstance(stmt, ast.Import):
                imported.update(a.name for a in stmt.names)
            elif isinstance(stmt, ast.ImportFrom):
                src = _resolve_from(name, stmt, mods)
                for a in stmt.names:
                    if f"{src}.{a.name}" in mods:
                        imported.add(f"{src}.{a.name}")
                    else:
                        imported.add(src)
                        taken.add((src, a.name))
    for line, text in _module_strings(name, root):
        inside = any(a <= line <= b for a, b in spans)
        if inside and not any(a <= line <= b for a, b in skipped) and text != name:
            strings.add(text)

    def ours(m: str) -> bool:
        return m == root.name or m.startswith(root.name + ".")

    return _Raw(
        frozenset(m for m in imported if ours(m)),
        frozenset(strings),
        frozenset(t for t in taken if ours(t[0])),
    )


_BLOCKS = ("body", "orelse", "finalbody", "handlers", "cases")


def _statements(nodes: Iterable[ast.AST], in_function: bool = False):
    """Yield ``(statement, inside a function)`` for ``nodes`` and every statement nested in
    them, except the body of ``if TYPE_CHECKING:``. A function statement itself is yielded
    with ``inside a function`` True (its body is)."""
    for node in nodes:
        inner = in_function or isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
        yield node, inner
        for field in _BLOCKS:
            if field == "body" and isinstance(node, ast.If) and _type_checking(node):
                continue
            for child in getattr(node, field, None) or ():
                if isinstance(child, (ast.ExceptHandler, ast.match_case)):
                    yield from _statements(child.body, inner)
                elif isinstance(child, ast.stmt):
                    yield from _statements([child], inner)


_MODULE_STRING = re.compile(r"""(getLogger\(\s*)?(["'])(\w+(?:\.\w+)*)\2""")


@functools.cache
def _module_strings(name: str, root: Path) -> tuple:
    """``(line, text)`` of each string literal in module ``name`` that names a scenebot
    module; a logger's name (``getLogger("scenebot.x")``) is no import."""
    mods = modules(root)
    out = []
    text = mods[name].read_text(encoding="utf-8")
    if root.name + "." not in text:
        return ()
    for k, line in enumerate(text.splitlines(), 1):
        for m in _MODULE_STRING.finditer(line):
            if m.group(1) is None and m.group(3) in mods:
                out.append((k, m.group(3)))
    return tuple(out)


def _type_checking(node: ast.If) -> bool:
    """``if TYPE_CHECKING:`` or ``if typing.TYPE_CHECKING:``."""
    test = node.test
    name = test.attr if isinstance(test, ast.Attribute) else getattr(test, "id", None)
    return name == "TYPE_CHECKING"


def _resolve_from(name: str, node: ast.ImportFrom, mods: dict[str, Path]) -> str:
    """The absolute module a ``from ... import`` statement in module ``name`` reads from."""
    if not node.level:
        return node.module or ""
    base = name.split(".")
    keep = len(base) - node.level + (1 if mods[name].name == "__init__.py" else 0)
    return ".".join(base[:keep] + ([node.module] if node.module else []))


def _raw(name: str, top_only: bool, root: Path = ROOT) -> _Raw:
    d = _facts(name, root)["top" if top_only else "full"]
    taken = frozenset(map(tuple, d["taken"]))
    return _Raw(frozenset(d["imported"]), frozenset(d["strings"]), taken)


def _bound(name: str, root: Path = ROOT) -> frozenset:
    return frozenset(_facts(name, root)["bound"])


def _bound_names(tree: ast.Module) -> list[str]:
    """Names bound at the top level of a module (defined, assigned or imported)."""
    names: set[str] = set()
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            names.update((a.asname or a.name).split(".")[0] for a in node.names)
        elif isinstance(node, (ast.Assign, ast.AnnAssign, ast.AugAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            for t in targets:
                names.update(n.id for n in ast.walk(t) if isinstance(n, ast.Name))
    return sorted(names)


# ------------------------------------------------------------------ the per-file cache
# Parsing every module takes about half a second; the facts of each file are kept in
# __pycache__/ beside the modules, keyed by the file's size and modification time, and all
# of them are dropped when this file or the set of modules changes.
CACHE = "scenebot-deps.json"


@functools.cache
def _cache(root: Path) -> dict:
    stamp = hashlib.sha1(Path(__file__).read_bytes())
    stamp.update("\n".join(modules(root)).encode())
    try:
        data = json.loads((root / "__pycache__" / CACHE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        data = {}
    if not isinstance(data, dict) or data.get("stamp") != stamp.hexdigest():
        data = {"stamp": stamp.hexdigest(), "modules": {}}
    data["dirty"] = False
    return data


def _save(root: Path) -> None:
    """Write the cache if it changed (best effort: a read-only install keeps none)."""
    data = _cache(root)
    if not data["dirty"]:
        return
    data["dirty"] = False
    folder = root / "__pycache__"
    tmp = folder / f".{CACHE}.{os.getpid()}"
    try:
        folder.mkdir(exist_ok=True)
        tmp.write_text(json.dumps(data), encoding="utf-8")
        os.replace(tmp, folder / CACHE)
    except OSError:
        tmp.unlink(missing_ok=True)


@functools.cache
def _facts(name: str, root: Path) -> dict:
    """What module ``name`` imports (anywhere, ``full``; at its module level, ``top``) and
    the names it binds, from the cache when its file has not changed."""
    path = modules(root)[name]
    st = path.stat()
    key = [st.st_size, st.st_mtime_ns]
    data = _cache(root)
    hit = data["modules"].get(name)
    if hit is not None and hit["key"] == key:
        return hit
    tree = _tree(path)

    def part(raw: _Raw) -> dict:
        return {"imported": sorted(raw.imported), "strings": sorted(raw.strings),
                "taken": sorted(raw.taken)}  # fmt: skip

    facts = {
        "key": key,
        "full": part(_collect(name, tree.body, root, functions=True)),
        "top": part(_collect(name, tree.body, root, functions=False)),
        "bound": _bound_names(tree),
    }
    data["modules"][name] = facts
    data["dirty"] = True
    return facts


def _is_lazy(name: str, root: Path) -> bool:
    """A package with a module ``__getattr__``: its strings are re-exports, loaded on use."""
    return modules(root)[name].name == "__init__.py" and "__getattr__" in _bound(name, root)


def _existing(name: str, mods: dict[str, Path]) -> str:
    """``name``, or the closest package above it that exists (``import a.b.attr``)."""
    while name and name not in mods:
        name = name.rpartition(".")[0]
    return name


def _resolve(raw: _Raw, name: str, root: Path) -> frozenset:
    """The scenebot modules that ``raw`` (a part of module ``name``) imports directly."""
    mods = modules(root)
    out = {_existing(m, mods) for m in raw.imported}
    if not _is_lazy(name, root):
        out |= raw.strings
    for package, attr in raw.taken:
        package = _existing(package, mods)
        if package and _is_lazy(package, root) and attr not in _bound(package, root):
            out |= _raw(package, False, root).strings
    out.discard(name)
    out.discard("")
    return frozenset(out)


@functools.cache
def module_imports(name: str, top_only: bool = False, root: Path = ROOT) -> frozenset:
    """The scenebot modules module ``name`` imports directly, anywhere in it (or at its
    module level only, ``top_only``); the packages above it are not included."""
    return _resolve(_raw(name, top_only, root), name, root)


def import_graph(root: Path = ROOT) -> dict[str, frozenset]:
    """Module -> the modules it imports directly (anywhere in it)."""
    graph = {m: module_imports(m, False, root) for m in modules(root)}
    _save(root)
    return graph


def _parents(name: str) -> list[str]:
    parts = name.split(".")
    return [".".join(parts[:k]) for k in range(1, len(parts))]


def closure(entries: Iterable[str], root: Path = ROOT, partial: Iterable[str] = ()) -> set[str]:
    """``entries`` and every scenebot module that using them may run: the modules they
    import, transitively, and the module level of every package above each. Of the modules
    ``partial`` (reached or not) only the module level is followed."""
    partial = set(partial)
    seen: set[tuple[str, bool]] = set()
    todo = [(m, False) for m in entries] + [(m, True) for m in partial]
    while todo:
        m, top_only = todo.pop()
        top_only = top_only or m in partial
        if (m, top_only) in seen or (m, False) in seen:
            continue
        seen.add((m, top_only))
        todo += [(n, False) for n in module_imports(m, top_only, root)]
        todo += [(p, True) for p in _parents(m)]
    return {m for m, _ in seen}


def _functions(name: str, root: Path) -> dict[str, ast.FunctionDef]:
    return {n.name: n for n in _tree(modules(root)[name]).body if isinstance(n, ast.FunctionDef)}


def _called(func: ast.FunctionDef, defined: dict[str, ast.FunctionDef]) -> list:
    """``func`` and the module's functions it calls by name, transitively (a function only
    named, as in ``set_defaults(func=cmd_sfm)``, is not called)."""
    out, todo = {}, [func]
    while todo:
        f = todo.pop()
        if f.name in out:
            continue
        out[f.name] = f
        for n in ast.walk(f):
            g = n.func if isinstance(n, ast.Call) else None
            if isinstance(g, ast.Name) and g.id in defined:
                todo.append(defined[g.id])
    return list(out.values())


def _always_run(cli: str, root: Path) -> tuple[set[str], list[str]]:
    """(modules, CLI modules) that the CLI module ``cli`` imports for every command: its
    module level, ``build_parser`` and ``main``, and the CLIs those add parsers from."""
    funcs = _functions(cli, root)
    tree = _tree(modules(root)[cli])
    raw = _collect(cli, tree.body, root, functions=False)
    run = [f for k in ALWAYS_RUN if k in funcs for f in _called(funcs[k], funcs)]
    raw2 = _collect(cli, run, root, functions=True)
    found = set(_resolve(raw, cli, root) | _resolve(raw2, cli, root))
    clis = [cli]
    for m in sorted(found):
        if m.rpartition(".")[2] == "cli" and m not in clis:
            more, sub = _always_run(m, root)
            found |= more
            clis += sub
    return found, clis


def command_entry(command: str, root: Path = ROOT) -> tuple[set[str], set[str]]:
    """Where ``python -m scenebot <command>`` starts (see the module doc).

    Returns:
        (``__main__`` and the CLI modules, which run only in part; the modules they import
        for this command).

    Raises:
        KeyError: no CLI module defines ``cmd_<command>``.
    """
    func = "cmd_" + command.replace("-", "_")
    found, clis = _always_run(f"{root.name}.cli", root)
    for cli in clis:
        funcs = _functions(cli, root)
        if func in funcs:
            found |= _resolve(_collect(cli, _called(funcs[func], funcs), root, True), cli, root)
            runs = {f"{root.name}.__main__", *clis}
            return runs, found - runs
    raise KeyError(f"no scenebot CLI module defines {func}() (command {command!r})")


def command_modules(command: str, root: Path = ROOT) -> set[str]:
    """Every scenebot module that ``python -m scenebot <command>`` may run."""
    runs, imported = command_entry(command, root)
    found = closure(imported, root, partial=runs)
    _save(root)
    return found


def command_files(command: str, root: Path = ROOT) -> list[str]:
    """The files of :func:`command_modules`, sorted (``rules/common.smk``'s code inputs)."""
    mods = modules(root)
    return sorted(str(mods[m]) for m in command_modules(command, root))


def refresh() -> None:
    """Forget the modules read so far (a process that edits them: the tests)."""
    for cached in (modules, _tree, _module_strings, _cache, _facts, module_imports):
        cached.cache_clear()
