"""The guide page of a round of a person's photos: ``round_XXX/guide/index.html``.

One static HTML file, everything inline (styles, script, pictures as data URIs), so that it
works from ``file://``, on a phone, copied anywhere, with no network. Generated from the
round's files only:

* the map (``round_XXX/sfm``: its points and the photos taken) from above and from the side,
  drawn as SVG with the next shots of ``goals.json`` as camera frusta;
* per shot: what to photograph (its preview from ``goals_preview.npz``, the part no photo
  sees in red), where to stand (the step from the nearest photo already taken,
  :mod:`scenebot.guide.advice`, that photo shown beside it) and the predicted gain (the
  shot's view score, degrees);
* the coverage picture (``goals.png``);
* where to put the new photos (the next round's inbox, :func:`scenebot.artifacts.inbox_dir`);
  served by ``scenebot guide serve``, the page also takes them by upload.

Clicking a shot (its card or its frustum) highlights it on both views and the photo to start
from. The page's data (round, units, per shot its pose, gain and step) is embedded as JSON
(``<script id="guide-data" type="application/json">``) for the script and for tests.
Entry point :func:`run` (the ``guide-page`` command, rule ``guide``).
"""

from __future__ import annotations

import base64
import html
import json
import logging
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from scenebot.artifacts import inbox_dir, round_index, round_name
from scenebot.artifacts.previews import read_previews
from scenebot.geometry import Intrinsics, frustum_lines, read_sparse_map
from scenebot.guide.advice import describe, nearest_photo, photo_poses, step_from
from scenebot.guide.config import GuideConfig

log = logging.getLogger(__name__)

MAP_WIDTH_PX = 640
"""Width of each map view (SVG user units; the page scales it to the screen)."""
MAP_POINTS = 2500
"""Most map points drawn per view (a seeded sample)."""
COVERAGE_WIDTH_PX = 1200
"""The coverage picture is shrunk to this width at most."""
SHOT_COLOURS = ("#e6194b", "#f58231", "#3cb44b", "#911eb4", "#f032e6", "#008080", "#9a6324",
                "#800000", "#808000", "#000075")  # fmt: skip
"""One colour per shot, in rank order (repeating)."""
VIEWS = {"top": (0, 1), "side": (0, 2)}
"""The map views: the axes drawn (x right, then y or z up)."""


@dataclass
class GuideInputs:
    """Inputs of the guide page: the round's map, the folder its image names are relative to,
    the goals, their previews and the coverage picture."""

    sfm_dir: Path
    image_dir: Path
    goals_json: Path
    preview_npz: Path
    coverage_png: Path


@dataclass
class GuideOutputs:
    """Output: the page (``round_XXX/guide/index.html``)."""

    guide_html: Path


class GuideInputError(ValueError):
    """A guide input is missing or does not fit the others (the message names the file)."""


def _asset(name: str) -> str:
    return resources.files("scenebot.guide").joinpath("assets", name).read_text(encoding="utf-8")


def _data_uri(img: np.ndarray, fmt: str = ".png", quality: int = 85) -> str:
    """An RGB (H, W, 3) uint8 image as a data URI."""
    import cv2

    params = [cv2.IMWRITE_JPEG_QUALITY, quality] if fmt == ".jpg" else []
    ok, buf = cv2.imencode(fmt, np.ascontiguousarray(img[..., ::-1]), params)
    if not ok:
        raise ValueError(f"could not encode a {img.shape} image as {fmt}")
    mime = "image/jpeg" if fmt == ".jpg" else "image/png"
    return f"data:{mime};base64," + base64.b64encode(buf.tobytes()).decode("ascii")


def _read_rgb(path: Path, width: int | None = None) -> np.ndarray:
    """An image file as RGB, shrunk to ``width`` at most."""
    import cv2

    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if img is None:
        raise GuideInputError(f"{path}: not a readable image")
    if width is not None and img.shape[1] > width:
        h = max(1, round(img.shape[0] * width / img.shape[1]))
        img = cv2.resize(img, (width, h), interpolation=cv2.INTER_AREA)
    return img[..., ::-1]


def _units(sfm_dir: Path) -> str:
    """ "m" when the map has a metric scale (sfm report.json's ``scale.source``), else
    "units" (SfM units)."""
    report = Path(sfm_dir) / "report.json"
    if not report.is_file():
        return "units"
    source = json.loads(report.read_text(encoding="utf-8")).get("scale", {}).get("source")
    return "m" if source not in (None, "none") else "units"


class _Frame:
    """The mapping of one view's two axes to SVG coordinates (equal scales, up is up): the
    view is ``width`` wide and 0.35 to 1.2 times as high, the drawing centred in it."""

    def __init__(self, pts: np.ndarray, width: float, pad: float = 0.06):
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        span = np.maximum(hi - lo, 1e-6)
        lo, hi = lo - pad * span.max(), hi + pad * span.max()
        span = hi - lo
        self.lo, self.hi = lo, hi
        self.s = float(min(width / span[0], 1.2 * width / span[1]))
        self.width = width
        self.height = float(max(span[1] * self.s, 0.35 * width))
        self.dx = 0.5 * (width - span[0] * self.s)
        self.dy = 0.5 * (self.height - span[1] * self.s)

    def xy(self, ab: np.ndarray) -> np.ndarray:
        ab = np.asarray(ab, np.float64)
        return np.stack([(ab[..., 0] - self.lo[0]) * self.s + self.dx,
                         (self.hi[1] - ab[..., 1]) * self.s + self.dy], axis=-1)  # fmt: skip


def _segments(segs: np.ndarray) -> str:
    """SVG path data of (N, 2, 2) line segments."""
    return "".join(f"M{a[0]:.1f} {a[1]:.1f}L{b[0]:.1f} {b[1]:.1f}" for a, b in segs)


def _scale_bar(frame: _Frame, unit: str) -> str:
    """A bar of a round length (1, 2 or 5 times a power of ten) of about a fifth of the view."""
    target = 0.2 * (frame.hi[0] - frame.lo[0])
    p = 10 ** np.floor(np.log10(target))
    length = max(m * p for m in (1, 2, 5) if m * p <= target)
    px = length * frame.s
    y = frame.height - 10
    label = f"{length:g} {'m' if unit == 'm' else 'units'}"
    return (f'<g class="scalebar"><path d="M10 {y:.1f}h{px:.1f}"/>'
            f'<text x="{10 + px / 2:.1f}" y="{y - 4:.1f}">{label}</text></g>')  # fmt: skip


def map_view(view: str, points: np.ndarray, taken: np.ndarray, names: list[str],
             shots: np.ndarray, intr: Intrinsics, unit: str) -> str:  # fmt: skip
    """One view of the map as SVG: the points, the photos taken (small frusta) and the shots
    (frusta in their colours, numbered by rank; shot 0 drawn on top of the others).

    Args:
        view: "top" (x, y) or "side" (x, z).
        points: (P, 3) map points.
        taken: (S, 5) the photos taken (x, y, z, theta, pitch).
        names: (S,) their file names.
        shots: (K, 5) the next shots, in rank order.
        intr: the camera (frusta).
        unit: "m" or "units".
    """
    a, b = VIEWS[view]
    cams = np.concatenate([taken[:, :3], shots[:, :3]]) if len(shots) else taken[:, :3]
    body = points
    if len(points) > 20:  # stray points far off do not shrink the view
        lo, hi = np.percentile(points, [2, 98], axis=0)
        body = points[np.all((points >= lo) & (points <= hi), axis=1)]
    extent = np.concatenate([body, cams]) if len(body) else cams
    depth = 0.12 * float(np.max(np.ptp(extent, axis=0))) if len(extent) > 1 else 0.3
    shot_segs = frustum_lines(shots, intr, depth) if len(shots) else np.zeros((0, 8, 2, 3))
    taken_segs = frustum_lines(taken, intr, 0.4 * depth)
    frame = _Frame(np.concatenate([extent[:, [a, b]], shot_segs[..., [a, b]].reshape(-1, 2)]),
                   MAP_WIDTH_PX)  # fmt: skip
    out = [f'<svg class="map" id="map-{view}" viewBox="0 0 {frame.width:.0f} '
           f'{frame.height:.0f}" xmlns="http://www.w3.org/2000/svg" role="img" '
           f'aria-label="the map from {"above" if view == "top" else "the side"}">',
           f'<rect class="bg" width="{frame.width:.0f}" height="{frame.height:.0f}"/>']  # fmt: skip
    if len(points):
        xy = frame.xy(points[:, [a, b]])
        out.append('<path class="pts" d="'
                   + "".join(f"M{x:.1f} {y:.1f}h1.6v1.6h-1.6z" for x, y in xy) + '"/>')  # fmt: skip
    for i, name in enumerate(names):
        segs = frame.xy(taken_segs[i][..., [a, b]])
        c = frame.xy(taken[i, [a, b]])
        out.append(f'<g class="taken" data-photo="{i}"><title>{html.escape(name)}</title>'
                   f'<path d="{_segments(segs)}"/><circle cx="{c[0]:.1f}" cy="{c[1]:.1f}" '
                   'r="2.5"/></g>')  # fmt: skip
    for k in reversed(range(len(shots))):  # the best shot last: on top, clickable where shots meet
        segs = frame.xy(shot_segs[k][..., [a, b]])
        c = frame.xy(shots[k, [a, b]])
        colour = SHOT_COLOURS[k % len(SHOT_COLOURS)]
        out.append(f'<g class="shot" data-rank="{k}" style="--c:{colour}" tabindex="0">'
                   f'<title>shot {k}</title><path d="{_segments(segs)}"/>'
                   f'<circle cx="{c[0]:.1f}" cy="{c[1]:.1f}" r="6"/>'
                   f'<text x="{c[0]:.1f}" y="{c[1] + 4:.1f}">{k}</text></g>')  # fmt: skip
    out.append(_scale_bar(frame, unit))
    label = "y" if b == 1 else "z (up)"
    out.append(f'<text class="axis" x="{frame.width - 6:.0f}" y="14">x →, {label} ↑</text>')
    out.append("</svg>")
    return "".join(out)


def _shot_card(k: int, shot: dict, preview_uri: str, photo_uri: str) -> str:
    """One shot's card: what to photograph, where to stand, the predicted gain."""
    colour = SHOT_COLOURS[k % len(SHOT_COLOURS)]
    gain = "?" if shot["score_deg"] is None else f"{shot['score_deg']:.1f}°"
    st, unit = shot["step"], shot["unit"]
    u = "m" if unit == "m" else "units"
    name = html.escape(shot["from_photo"])
    return f"""
<article class="shot-card" id="shot-{k}" data-rank="{k}" style="--c:{colour}" tabindex="0">
 <h3><span class="badge">{k}</span> Shot {k}
  <span class="gain" title="the view score: the rendering error a photo here removes">predicted
  gain <b>{gain}</b></span></h3>
 <div class="pair">
  <figure><img class="preview" src="{preview_uri}" alt="what shot {k} should show">
   <figcaption><b>What to photograph</b>: the view from here, rendered from your photos;
   red: what no photo shows yet ({100 * shot["missing_fraction"]:.0f}% of the view).
   </figcaption></figure>
  <figure><img class="from-photo" src="{photo_uri}" alt="{name}">
   <figcaption><b>Start from</b> {name}</figcaption></figure>
 </div>
 <p class="advice">{html.escape(shot["advice"])}</p>
 <table class="step"><tr><th>forward</th><th>right</th><th>up</th><th>distance</th>
  <th>turn left</th><th>tilt up</th></tr>
  <tr><td>{st["forward"]:.2f} {u}</td><td>{st["right"]:.2f} {u}</td><td>{st["up"]:.2f} {u}</td>
  <td>{st["distance"]:.2f} {u}</td><td>{st["turn_deg"]:.0f}°</td><td>{st["pitch_deg"]:.0f}°</td>
  </tr></table>
 <button type="button" class="skip" data-skip="{k}" hidden>I cannot take this shot</button>
</article>"""


def page_data(goals_doc: dict, smap, units: str, previews, where: str,
              inbox: Path) -> tuple[dict, np.ndarray, np.ndarray]:  # fmt: skip
    """The page's data (embedded as JSON) and the shots' and photos' poses.

    Returns:
        (data, shots (K, 5), taken (S, 5)).
    """
    goals = goals_doc.get("goals", [])
    if goals and "z" not in goals[0]:
        raise GuideInputError(
            f"{where}: the goals have no height (z, pitch); the guide is for a person's photos "
            "(robot: photos)"
        )
    if [int(r) for r in previews.ranks] != [g["rank"] for g in goals]:
        raise GuideInputError(
            f"{where}: the previews are of shots {list(previews.ranks)} but goals.json "
            f"advises {[g['rank'] for g in goals]}; re-run the goals_preview rule"
        )
    taken = photo_poses(smap.R, smap.centres)
    shots = np.array([[g[c] for c in ("x", "y", "z", "theta", "pitch")] for g in goals],
                     np.float64).reshape(-1, 5)  # fmt: skip
    records = []
    for k, g in enumerate(goals):
        i = nearest_photo(shots[k], taken)
        step = step_from(taken[i], shots[k])
        records.append({
            **{c: g[c] for c in ("rank", "x", "y", "z", "theta", "pitch", "score_deg")},
            "missing_fraction": round(previews.missing_fraction(k), 4),
            "from_photo": smap.names[i], "from_index": i,
            "step": step.as_dict(), "unit": units,
            "advice": describe(step, smap.names[i], units),
        })  # fmt: skip
    data = {
        "round": goals_doc.get("round", where),
        "complete": bool(goals_doc.get("complete", False)),
        "why": goals_doc.get("complete_because") or goals_doc.get("not_complete_because"),
        "units": units,
        "photos_mapped": len(smap.names),
        "inbox": inbox.as_posix() + "/",
        "shots": records,
    }
    return data, shots, taken


def render_page(data: dict, maps: dict[str, str], cards: list[str], coverage_uri: str) -> str:
    """The whole page (every asset inline)."""
    n = len(data["shots"])
    if data["complete"]:
        status = ("The map is <b>complete</b>: no view is predicted to render poorly "
                  f"({html.escape(str(data['why'] or ''))}).")  # fmt: skip
        if n:
            status += " The shots below would still add a little."
    else:
        status = f"The next <b>{n}</b> shot{'s' if n != 1 else ''}, best first."
    units = ("lengths in metres" if data["units"] == "m" else
             "lengths in map units (the map has no metric scale: sfm.known_distance gives "
             "one)")  # fmt: skip
    inbox = html.escape(data["inbox"])
    payload = json.dumps(data, ensure_ascii=False).replace("</", "<\\/")
    title = f"scenebot guide: {html.escape(data['round'])}"
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<link rel="icon" href="data:,">
<title>{title}</title>
<style>{_asset("guide.css")}</style>
</head><body>
<header><h1>{title}</h1>
<p>{status} {data["photos_mapped"]} photos mapped; {units}.
Tap a shot to see it on the map.</p></header>
<section id="maps"><h2>The map and the next shots</h2>
<div class="views"><figure><figcaption>From above</figcaption>{maps["top"]}</figure>
<figure><figcaption>From the side</figcaption>{maps["side"]}</figure></div>
<p class="legend"><span class="key taken-key"></span> photos taken
<span class="key shot-key"></span> next shots (number = rank)</p></section>
<section id="shots"><h2>Shots</h2>{"".join(cards) or "<p>No shot advised.</p>"}</section>
<section id="send"><h2>Your new photos</h2>
<p>Put them in <code>{inbox}</code>; the next <code>snakemake</code> run adds them to the
map. Or run <code>python -m scenebot guide serve --host 0.0.0.0</code> and open the address
it prints on your phone to take and upload them here.</p>
<form id="upload" hidden action="upload" method="post" enctype="multipart/form-data">
<input type="file" name="photos" accept="image/jpeg,image/png" multiple>
<button type="submit">Upload</button><p id="upload-limit"></p><ul id="upload-result"></ul>
</form></section>
<section id="coverage"><h2>Coverage</h2>
<p>The map's surface coloured by how many photos see it (red crosses: fewer than 2), with
the shots from above and from the side.</p>
<img class="coverage" src="{coverage_uri}" alt="coverage of the map's surface"></section>
<script id="guide-data" type="application/json">{payload}</script>
<script>{_asset("guide.js")}</script>
</body></html>
"""


def run(cfg: GuideConfig, inputs: GuideInputs, outputs: GuideOutputs) -> dict:
    """Write the guide page of a round.

    Args:
        cfg: guide settings (``guide.photo_width``).
        inputs: the round's map, photo folder, goals, previews and coverage picture.
        outputs: the page.

    Returns:
        Summary: round, shots (rank, from photo, distance), page size (bytes).
    """
    where = round_name(inputs.goals_json, outputs.guide_html)
    doc = json.loads(Path(inputs.goals_json).read_text(encoding="utf-8"))
    smap = read_sparse_map(inputs.sfm_dir)
    if not smap.names:
        raise GuideInputError(f"{inputs.sfm_dir}: the map holds no registered photo")
    previews = read_previews(inputs.preview_npz)
    out = Path(outputs.guide_html)
    r = round_index(out.parent.parent.name) or round_index(where) or 0
    inbox = inbox_dir(out.parent.parent.parent, r)
    units = _units(inputs.sfm_dir)
    data, shots, taken = page_data(doc, smap, units, previews, where, inbox)
    rng = np.random.default_rng(0)
    pts = smap.xyz
    if len(pts) > MAP_POINTS:
        pts = pts[np.sort(rng.choice(len(pts), MAP_POINTS, replace=False))]
    intr = smap.intrinsics[0]
    maps = {v: map_view(v, pts, taken, smap.names, shots, intr, units) for v in VIEWS}
    cards = []
    for k, shot in enumerate(data["shots"]):
        photo = Path(inputs.image_dir) / shot["from_photo"]
        cards.append(_shot_card(k, shot, _data_uri(previews.images[k]),
                                _data_uri(_read_rgb(photo, cfg.photo_width), ".jpg")))  # fmt: skip
    coverage = _data_uri(_read_rgb(Path(inputs.coverage_png), COVERAGE_WIDTH_PX), ".jpg", 90)
    page = render_page(data, maps, cards, coverage)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".tmp")
    tmp.write_text(page, encoding="utf-8")
    tmp.replace(out)
    summary = {
        "round": data["round"],
        "shots": [
            {"rank": s["rank"], "from_photo": s["from_photo"], "distance": s["step"]["distance"]}
            for s in data["shots"]
        ],
        "inbox": data["inbox"],
        "bytes": out.stat().st_size,
    }
    log.info("guide page: %s", summary)
    return summary
