"""Bring-your-own photos: the sfm stage against plain pycolmap on real photos with known cameras.

The Middlebury ``templeSparseRing`` set (16 real 640x480 photos on a ring, no EXIF, some
rolled 90 or 180 degrees; calibrated cameras in ``templeSR_par.txt``, metres) is copied to a
temporary folder and mapped twice in the same run:

* the figure: scenebot's sfm stage with the default settings (``robot: photos``: a photo
  folder), plots off;
* the references: plain pycolmap on the same copy: ``extract_features``,
  ``match_exhaustive``, ``incremental_mapping`` with default options (largest model),
  ``pycolmap`` with every default (photos without EXIF get a camera each: CameraMode.AUTO)
  and ``pycolmap_single`` with one shared camera (``camera_mode=CameraMode.SINGLE``, as
  scenebot shares one camera among photos of one size and focal).

Each model's camera centres are fitted to the given ones by a similarity (Umeyama, least
squares); the error of a photo is the distance of its fitted centre from the given centre,
in millimetres of the given (metric) frame. Rows: wall time (s) against each reference,
with registered photos and median and max centre error in the note. Previously measured:
plain pycolmap 13 of 16, 1.93 mm median (the shared-camera figure; with every default
14 mm: 13 focal lengths refined on their own). Acceptance (issue 25): scenebot 16 of 16
with a median error no worse.

    .venv/bin/python benchmarks/bench_byo_sfm.py [--data DIR] [--repeats N]

The data folder defaults to ``../shared/data/temple-sparse-ring`` beside the repository
(``SCENEBOT_TEMPLE_DIR`` overrides it); it is only read.
"""

from __future__ import annotations

import argparse
import logging
import os
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))  # measure this checkout's scenebot, as run.py does
PAR_FILE = "templeSR_par.txt"


def temple_dir() -> Path:
    """The temple photos: ``$SCENEBOT_TEMPLE_DIR``, else ``../shared/data/temple-sparse-ring``
    beside the repository."""
    env = os.environ.get("SCENEBOT_TEMPLE_DIR")
    return Path(env) if env else ROOT.parent / "shared" / "data" / "temple-sparse-ring"


def read_par(path: Path) -> dict[str, np.ndarray]:
    """Camera centres of a Middlebury ``*_par.txt`` (first line the count, then
    ``name k11..k33 r11..r33 t1 t2 t3`` per photo, world to camera): photo name -> (3,)
    centre ``-R^T t`` (metres, the set's frame); read by the evaluation's reader."""
    from scenebot.evaluate.reference import read_reference_cameras

    return {name: centre for name, (_, centre) in read_reference_cameras(path).items()}


def centre_errors_mm(rec, given: dict[str, np.ndarray]) -> dict[str, float]:
    """Per registered photo: distance (mm) of its camera centre, after the least-squares
    similarity onto the ``given`` centres (m), from its given centre."""
    from scenebot.sfm.evaluate import umeyama

    names = [rec.image(i).name for i in rec.reg_image_ids() if rec.image(i).name in given]
    if len(names) < 3:
        return {}
    by_name = {rec.image(i).name: rec.image(i) for i in rec.reg_image_ids()}
    src = np.array([by_name[n].projection_center() for n in names])
    dst = np.array([given[n] for n in names])
    s, R, t = umeyama(src, dst)
    err = np.linalg.norm(s * src @ R.T + t - dst, axis=1) * 1000.0
    return dict(zip(names, err.tolist(), strict=True))


def run_scenebot(photos: Path, work: Path):
    """The sfm stage with the default settings on a photo folder; (model, report, s)."""
    import pycolmap

    from scenebot.sfm.config import SfmConfig
    from scenebot.sfm.stage import SfmInputs, SfmOutputs, run

    out = SfmOutputs(work / "sfm")
    t = time.perf_counter()
    report = run(
        SfmConfig(plots=False), SfmInputs(work / "db" / "database.db", photo_folder=photos), out
    )
    seconds = time.perf_counter() - t
    return pycolmap.Reconstruction(str(out.model_dir)), report, seconds


REFERENCES = {
    "pycolmap": "plain pycolmap defaults (extract, exhaustive match, incremental mapping)",
    "pycolmap_single": "plain pycolmap defaults, one shared camera (CameraMode.SINGLE)",
}
"""The same-run references: key -> description."""


def run_pycolmap(photos: Path, work: Path, single_camera: bool):
    """Plain pycolmap: extract (default options; ``single_camera``: one camera for all
    photos), exhaustive matching, incremental mapping; the largest model (None when none)
    and seconds."""
    import pycolmap

    work.mkdir(parents=True, exist_ok=True)
    db, out = work / "database.db", work / "models"
    out.mkdir(exist_ok=True)
    t = time.perf_counter()
    mode = pycolmap.CameraMode.SINGLE if single_camera else pycolmap.CameraMode.AUTO
    pycolmap.extract_features(str(db), str(photos), camera_mode=mode)
    pycolmap.match_exhaustive(str(db))
    models = pycolmap.incremental_mapping(str(db), str(photos), str(out))
    seconds = time.perf_counter() - t
    best = max(models.values(), key=lambda r: r.num_reg_images(), default=None)
    return best, seconds


def compare(data: Path, work: Path, references: tuple[str, ...] = tuple(REFERENCES)) -> dict:
    """scenebot and the ``references`` (keys of :data:`REFERENCES`) on a copy of ``data``
    under ``work`` (the copy only is read).

    Returns:
        ``{"photos": n, "scenebot": {...}, <reference>: {...}, "report": report,
        "model_dir": Path}`` where each pipeline has ``registered``, ``seconds``,
        ``median_mm``, ``max_mm`` and ``errors_mm`` (per photo).
    """
    from scenebot.sfm.photofiles import photo_files

    photos = work / "photos"
    shutil.copytree(data, photos)
    given = read_par(photos / PAR_FILE)
    rec, report, s_ours = run_scenebot(photos, work / "scenebot")
    runs = [("scenebot", rec, s_ours)]
    for key in references:
        runs.append((key, *run_pycolmap(photos, work / key, key == "pycolmap_single")))
    out = {"photos": len(photo_files(photos)), "report": report}
    out["model_dir"] = work / "scenebot" / "sfm"
    for key, model, seconds in runs:
        err = centre_errors_mm(model, given) if model is not None else {}
        vals = list(err.values())
        out[key] = {
            "registered": 0 if model is None else model.num_reg_images(),
            "seconds": seconds,
            "median_mm": float(np.median(vals)) if vals else float("nan"),
            "max_mm": float(np.max(vals)) if vals else float("nan"),
            "errors_mm": err,
        }
    return out


def measure(data: Path, repeats: int = 1, echo: bool = True) -> list[dict]:
    """``repeats`` comparisons, each on a fresh temporary copy; rows in benchmarks/run.py
    form (median seconds; accuracy of the last run in the note)."""
    runs = []
    for _ in range(repeats):
        with tempfile.TemporaryDirectory(prefix="bench_byo_sfm_") as tmp:
            res = compare(data, Path(tmp))
            res.pop("model_dir")
            runs.append(res)
    last = runs[-1]
    ours, n = last["scenebot"], last["photos"]

    def acc(d: dict) -> str:
        return (f"{d['registered']}/{n} registered, centre error median {d['median_mm']:.2f} "
                f"mm, max {d['max_mm']:.2f} mm")  # fmt: skip

    name = f"sfm stage (defaults), temple ring, {n} real 640x480 photos, no EXIF"
    rows = [
        {
            "group": "byo_sfm",
            "name": name,
            "median": statistics.median(r["scenebot"]["seconds"] for r in runs),
            "unit": "s",
            "repeats": repeats,
            "reference": REFERENCES[key],
            "reference_median": statistics.median(r[key]["seconds"] for r in runs),
            "note": f"scenebot {acc(ours)} (mapper {last['report']['mapper']}); reference "
            f"{acc(last[key])}; errors after a similarity fit to the given cameras",
        }
        for key in REFERENCES
    ]
    if echo:
        print(f"bring-your-own photos: {data} ({n} photos), repeats={repeats}, "
              f"cores={os.cpu_count()}, load {os.getloadavg()[0]:.1f}")  # fmt: skip
        print(f"{'pipeline':<74}{'registered':>11}{'median mm':>11}{'max mm':>8}{'s':>7}")
        labels = {"scenebot": "scenebot sfm stage (defaults)", **REFERENCES}
        for key, label in labels.items():
            d = last[key]
            print(f"{label:<74}{d['registered']:>7}/{n:<3}{d['median_mm']:>11.2f}"
                  f"{d['max_mm']:>8.2f}{d['seconds']:>7.1f}")  # fmt: skip
        print("per photo (mm, " + " / ".join(labels) + "): " + ", ".join(
            f"{k[-8:-4]} " + "/".join(f"{last[p]['errors_mm'].get(k, float('nan')):.1f}"
                                      for p in labels)
            for k in sorted(ours["errors_mm"])
        ))  # fmt: skip
    return rows


def bench(quick: bool) -> list[dict]:
    """Rows for benchmarks/run.py (none without the temple photos)."""
    data = temple_dir()
    if not (data / PAR_FILE).is_file():
        return []
    return measure(data, repeats=1 if quick else 3, echo=False)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=temple_dir(), help="the temple photo folder")
    ap.add_argument("--repeats", type=int, default=1)
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    if not (args.data / PAR_FILE).is_file():
        print(f"no {PAR_FILE} in {args.data}: pass --data or set SCENEBOT_TEMPLE_DIR")
        return 1
    measure(args.data, args.repeats)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
