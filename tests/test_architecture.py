"""The import graph of scenebot (DESIGN.md sections 1 and 5): no import circles, and
dependencies point down: the CLI, then the stages (which do not import each other, but for the
crossings listed and explained in pyproject.toml), then the robot, the simulator and the
shared modules, which import no stage.

The layers are import-linter contracts in pyproject.toml (``[tool.importlinter]``); the
circles are found on :mod:`scenebot._deps`'s graph, which counts imports inside functions and
the modules that lazy re-exports name. Each check is also shown failing on a planted import.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from scenebot import _deps
from tests.fixtures.package import copy_package

REPO = Path(__file__).resolve().parents[1]


def circles(graph: dict[str, frozenset]) -> list[list[str]]:
    """One shortest import circle through each group of modules that import each other."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    groups: list[set[str]] = []

    def visit(v: str) -> None:  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = set()
            while True:
                w = stack.pop()
                on_stack.discard(w)
                group.add(w)
                if w == v:
                    break
            if len(group) > 1 or v in graph.get(v, ()):
                groups.append(group)

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return [_circle(graph, g) for g in groups]


def _circle(graph: dict[str, frozenset], group: set[str]) -> list[str]:
    """A shortest path from the group's first module back to itself, inside the group."""
    start = min(group)
    paths = {start: [start]}
    todo = [start]
    while todo:
        v = todo.pop(0)
        for w in sorted(graph.get(v, ())):
            if w == start:
                return [*paths[v], start]
            if w in group and w not in paths:
                paths[w] = [*paths[v], w]
                todo.append(w)
    return sorted(group)


def test_no_import_circles_among_scenebot_modules():
    found = circles(_deps.import_graph())
    assert not found, "import circles:\n" + "\n".join(" -> ".join(c) for c in found)


def lint_imports(cwd: Path) -> subprocess.CompletedProcess:
    """import-linter's contracts of ``cwd/pyproject.toml`` on the package ``cwd/scenebot``."""
    code = "import sys; from importlinter.cli import lint_imports; "
    code += "sys.exit(lint_imports(no_cache=True, no_logo=True))"
    env = {**os.environ, "PYTHONPATH": str(cwd)}
    return subprocess.run(
        [sys.executable, "-c", code], cwd=cwd, env=env, capture_output=True, text=True,
        timeout=600, check=False,
    )  # fmt: skip


def test_import_contracts_hold():
    res = lint_imports(REPO)
    assert res.returncode == 0, res.stdout + res.stderr
    assert "BROKEN" not in res.stdout and "0 broken" in res.stdout


@pytest.fixture
def package_copy(tmp_path) -> Path:
    """A copy of the package's modules and of pyproject.toml, to plant imports in."""
    copy_package(tmp_path)
    shutil.copy(REPO / "pyproject.toml", tmp_path)
    yield tmp_path
    _deps.refresh()


def plant(root: Path, module: str, statement: str) -> None:
    """Add ``statement`` to ``module`` (a path under scenebot/) inside a function: imports
    made where they are used count as much as those at the top."""
    path = root / "scenebot" / module
    path.write_text(
        path.read_text(encoding="utf-8") + f"\n\ndef _planted():\n    {statement}\n",
        encoding="utf-8",
    )


@pytest.mark.parametrize(
    ("module", "statement", "reported"),
    [
        # the robot layer reaches up into a stage (what robot/nxt/backend.py used to do)
        ("robot/nxt/backend.py", "from scenebot.capture.stage import run_capture",
         "scenebot.robot.nxt.backend -> scenebot.capture.stage"),
        # a shared module imports a stage
        ("geometry.py", "import scenebot.sfm.stage", "scenebot.geometry -> scenebot.sfm.stage"),
        # a new crossing between two stages, not in the contract's list
        ("tour/stage.py", "from scenebot.plan.stage import read_goals",
         "scenebot.tour.stage -> scenebot.plan.stage"),
        # a stage imports the test fixtures
        ("dense/stage.py", "import scenebot.testing.dense",
         "scenebot.dense.stage -> scenebot.testing.dense"),
    ],
)  # fmt: skip
def test_a_planted_upward_or_crossing_import_breaks_the_contract(
    package_copy, module, statement, reported
):
    plant(package_copy, module, statement)
    res = lint_imports(package_copy)
    assert res.returncode == 1, res.stdout + res.stderr
    assert "BROKEN" in res.stdout and reported in res.stdout, res.stdout


def test_a_module_outside_every_layer_breaks_the_contract(package_copy):
    (package_copy / "scenebot" / "newstage.py").write_text('"""A stage of its own."""\n')
    res = lint_imports(package_copy)
    assert res.returncode == 1 and "scenebot.newstage" in res.stdout, res.stdout


def test_a_planted_circle_is_found(package_copy):
    # adaptive imports explore; explore importing adaptive back closes a circle
    plant(package_copy, "capture/explore.py", "from scenebot.capture.adaptive import goal_headings")
    found = circles(_deps.import_graph(package_copy / "scenebot"))
    loop = ["scenebot.capture.adaptive", "scenebot.capture.explore", "scenebot.capture.adaptive"]
    assert loop in found
