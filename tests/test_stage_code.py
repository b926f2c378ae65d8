"""The code a rule depends on is computed from the imports (scenebot/_deps.py, called by
rules/common.smk's ``stage_code``): every module a command runs is there, a new import shows
up, and the other commands' modules are not."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from scenebot import _deps
from tests.fixtures.package import copy_package

REPO = Path(__file__).resolve().parents[1]
PKG = REPO / "scenebot"


def code(command: str, root: Path = PKG) -> set[str]:
    """The files of ``command`` relative to the package folder."""
    return {Path(f).relative_to(root).as_posix() for f in _deps.command_files(command, root)}


def test_every_rule_names_a_command_and_gets_its_cli_and_stage():
    used = set()
    for smk in (REPO / "rules").glob("*.smk"):
        used |= set(re.findall(r'stage_code\("([\w-]+)"\)', smk.read_text(encoding="utf-8")))
    assert {"sfm", "mesh", "score", "goals", "plan", "dense", "tour", "campaign"} <= used
    for command in used:
        files = code(command)
        assert {"__main__.py", "cli.py", "config.py"} <= files, command


def test_the_files_the_hand_written_list_missed_are_there():
    # issue 21: goals missed the candidates' and the free space's readers (now in the shared
    # artifacts/), the map's geometry and plan/stage.py (read_map_geometry, now in the shared
    # scenebot/geometry.py)
    assert {"artifacts/candidates.py", "artifacts/freespace.py", "geometry.py",
            "goals/stage.py", "goals/select.py", "goals/stopping.py"} <= code("goals")  # fmt: skip
    # and it runs none of the score stage's code
    assert not any(f.startswith("score/") and not f.endswith(("config.py", "__init__.py"))
                   for f in code("goals"))  # fmt: skip
    # campaign missed adaptive.py (map_fingerprint, now in the capture log's module)
    assert {"campaign.py", "capturelog.py"} <= code("campaign")
    # plan listed score/geometry.py, which it does not import
    assert "plan/stage.py" in code("plan") and "score/geometry.py" not in code("plan")


def test_lazy_and_function_level_imports_count():
    # evaluate/__init__ re-exports lazily; the evaluate command imports its stage in a function
    assert {"evaluate/stage.py", "evaluate/observable.py", "scene/loader.py"} <= code("evaluate")
    # the built-in scenes are imported by name (importlib) from scene/loader.py
    scenes = {"scene/office.py", "scene/flat.py", "scene/rooms.py", "scene/parts.py"}
    assert scenes <= code("evaluate")


def test_other_commands_code_is_not_followed():
    sfm = code("sfm")
    assert "sfm/stage.py" in sfm
    assert not any(f.startswith(("score/", "tour/", "dense/")) and not f.endswith(
        ("config.py", "__init__.py")) for f in sfm)  # fmt: skip
    assert "tour/ulr.py" not in code("plan") and "score/kernel.py" not in code("dense")
    assert "score/kernel.py" not in code("mesh") and "mesh/poisson.py" not in code("score")


def test_an_unknown_command_is_an_error():
    with pytest.raises(KeyError, match="cmd_nope"):
        _deps.command_files("nope")


@pytest.fixture
def package_copy(tmp_path) -> Path:
    yield copy_package(tmp_path)
    _deps.refresh()


def test_a_planted_import_shows_up_also_after_the_cache_was_written(package_copy):
    before = code("plan", package_copy)
    assert "tour/path.py" not in before
    assert (package_copy / "__pycache__" / _deps.CACHE).is_file()
    astar = package_copy / "plan" / "astar.py"
    text = astar.read_text(encoding="utf-8")
    astar.write_text(text + "\n\ndef _planted():\n    from scenebot.tour import path\n")
    _deps.refresh()  # a new process: only the cache on disk is left
    added = code("plan", package_copy) - before
    assert "tour/path.py" in added and all(f.startswith("tour/") for f in added), added
