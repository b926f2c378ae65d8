"""``skipped.json``: the shots of a guide the person could not take, in the next round's inbox
beside the photos (written by ``scenebot guide skip``, the guide page's "cannot take it" button
through ``guide serve``, and the simulated person; read by the round's capture, which logs
them as ``shots_skipped``: :func:`scenebot.capturelog.skipped_shots`).

``{"shots": [{"rank": 3, "reason": "behind a wall"}, ...]}``: ranks as in goals.json and on
the guide page.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

SKIPPED = "skipped.json"


def read_skipped(inbox: str | Path) -> dict[int, str]:
    """Rank -> why of the shots in ``inbox/skipped.json``; empty without the file.

    Raises:
        ValueError: the file is not such a list (named, with the fix).
    """
    path = Path(inbox) / SKIPPED
    if not path.is_file():
        return {}
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        return {int(s["rank"]): str(s.get("reason") or "") for s in doc.get("shots", [])}
    except (ValueError, KeyError, TypeError, AttributeError) as exc:
        raise ValueError(
            f"{path} is not a list of skipped shots ({exc}): write it with python -m "
            "scenebot guide skip, or delete it"
        ) from exc


def write_skipped(inbox: str | Path, shots: dict[int, str]) -> Path:
    """Add shots the person could not take (rank -> why) to ``inbox/skipped.json`` (made with
    the inbox when missing); a shot already there keeps its first reason. Written whole or
    not at all."""
    inbox = Path(inbox)
    inbox.mkdir(parents=True, exist_ok=True)
    merged = {**{int(k): v for k, v in shots.items()}, **read_skipped(inbox)}
    doc = {"shots": [{"rank": k, "reason": merged[k]} for k in sorted(merged)]}
    tmp = inbox / f".{SKIPPED}.{os.getpid()}.part"
    tmp.write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    os.replace(tmp, inbox / SKIPPED)
    return inbox / SKIPPED
