# Helpers shared by all rules: config validation, stage parameters, code inputs.
import json
import shlex
import sys
from pathlib import Path
from types import SimpleNamespace

from snakemake.utils import validate

from scenebot._deps import command_files
from scenebot.config import (
    ConfigError,
    check_config_files,
    normalize_config,
    section_json,
    validate_config,
)
from scenebot.capture.predict import SCORE_SETTINGS
from scenebot.sfm.photofiles import photo_files

# A wrong value stops the workflow here, naming the key and what to write (the typed model
# first, for its messages; then the JSON schema generated from it, which sees the values as
# the model read them: "12" for a whole number is 12, as nested --config values are text).
try:
    check_config_files(workflow.overwrite_configfiles or [])
    CFG = validate_config(config, "the workflow config (config.yaml and --config)")
except ConfigError as exc:
    raise WorkflowError(str(exc)) from None
config.update(normalize_config(config, CFG))
validate(config, schema="../scenebot/config.schema.json", set_default=False)

PY = sys.executable  # there is no bare `python` on PATH outside the virtualenv
# the multi-threaded stages take every core of the run; commands that run nothing
# (--report, --summary, --lint) give no --cores, and the threads then do not matter
try:
    ALL_CORES = workflow.cores
except WorkflowError:
    ALL_CORES = 1
SCENE = CFG.scene
RESULTS = f"results/{SCENE}"
PKG = Path(workflow.basedir) / "scenebot"
MODEL_FILES = ["cameras.bin", "images.bin", "points3D.bin"]
# the guide page's styles and script, copied into every page (not Python: not in stage_code)
GUIDE_ASSETS = sorted(str(p) for p in (PKG / "guide" / "assets").glob("*.*"))


# The code each stage runs: a change re-runs exactly the stages that use it. The captures are
# not listed: photos are data, re-taken when capture settings change (or with --forcerun).
def stage_code(command):
    """The package files that `python -m scenebot <command>` runs (the rule's code input),
    computed from the imports: scenebot/_deps.py."""
    return command_files(command, PKG)


def stage_params(*sections):
    """The config sections a stage reads, as canonical JSON (a change re-runs it)."""
    return section_json(CFG, "scene", "robot", "seed", *sections)


PHOTOS = CFG.robot == "photos"  # bring-your-own photos: round 0 is a folder, no robot
PERSON = (
    CFG.person_photos()
)  # a person's photos (photos, guided, person-sim): 6 DoF, shots
GUIDED = CFG.guided_rounds()  # guided rounds: each round's photos from its inbox
PERSON_SIM = CFG.robot == "person-sim"  # the simulated person fills the inbox


def campaign_targets(wildcards):
    """What `snakemake` builds by default: the whole campaign, its products and (simulated
    robots) its evaluation against the truth, per round and final."""
    return [*timed_products(wildcards), f"{RESULTS}/timing.json"]


def timed_products(wildcards):
    """The campaign's products whose jobs' times timing.json sums (every target but itself)."""
    targets = [
        f"{RESULTS}/campaign.json",
        f"{RESULTS}/final/dense/fused.ply",
        f"{RESULTS}/final/tour/index.html",
    ]
    return targets + (evaluation_products(wildcards) if EVALUATED else [])


def round_dir(r):
    return f"{RESULTS}/round_{int(r):03d}"


def campaign_rounds():
    """The rounds the campaign runs: 0, then one more while the last round's decisions (the
    plan checkpoint, after goals.json) say the map is incomplete, up to max_rounds."""
    rounds = [0]
    while len(rounds) < CFG.round_limit():
        r = f"{rounds[-1]:03d}"
        round_checkpoint(r)
        goals = Path(f"{RESULTS}/round_{r}/goals.json")
        if json.loads(goals.read_text(encoding="utf-8"))["complete"]:
            break
        rounds.append(rounds[-1] + 1)
    return rounds


def round_checkpoint(r):
    """The last decision of round ``r`` (a checkpoint): the plan of a robot's round, the
    guide page of a guided round (a person follows it)."""
    if GUIDED:
        return checkpoints.guide.get(r=r)
    return checkpoints.plan.get(r=r)


def round_products(wildcards):
    """Every file each round of the campaign leaves (maps, decisions, pictures)."""
    files = []
    for r in campaign_rounds():
        d = round_dir(r)
        if not (PHOTOS and r == 0):
            files += [f"{d}/capture/log.jsonl", f"{d}/capture/trajectory.png"]
        files += [f"{d}/sfm/{f}" for f in ("report.json", "map.png")]
        files += [f"{d}/{f}" for f in ("goals.json", "goals.png")]
        if PERSON:  # each advised shot rendered from the photos (rule goals_preview)
            files.append(f"{d}/goals_preview.png")
            # the person's guide page (rule guide)
            files.append(f"{d}/guide/index.html")
        if (
            GUIDED and r > 0
        ):  # the shots of the previous guide this round's photos fulfilled
            files.append(f"{d}/fulfilment.json")
        if not PERSON:  # a person's photos: no robot to plan paths for
            files += [f"{d}/{f}" for f in ("paths.json", "navgrid.png")]
    return files


def last_round_model(wildcards):
    """The map of the campaign's last round (dense and the tour use it)."""
    return [f"{round_dir(campaign_rounds()[-1])}/sfm/{f}" for f in MODEL_FILES]


def previous_round(wildcards):
    """What adaptive capture of round r waits for: round r-1's decisions (map, goals, paths,
    grid: the plan checkpoint) and photos. Only round r-1's capture log is an input: rebuilding
    a map or a decision later never re-takes round r's photos; re-taking round r-1 does.
    """
    prev = f"{int(wildcards.r) - 1:03d}"
    round_checkpoint(prev)
    return [f"{RESULTS}/round_{prev}/capture/log.jsonl"] + inbox_input(wildcards)


def inbox_input(wildcards):
    """A guided round's photos, in its inbox (the round's capture takes them in): the person's
    photos there now (a photo added later re-takes the round), or the simulated person's
    record of its shots (rule person_sim). Empty for a robot's round."""
    if not GUIDED:
        return []
    inbox = f"{RESULTS}/round_{wildcards.r}/capture/inbox"
    if PERSON_SIM:
        return [f"{inbox}/person-sim.jsonl"]
    return [str(p) for p in photo_files(inbox)]


def round0_photos(wildcards):
    """robot: guided: the photo folder that round 0 takes in (a change re-takes it)."""
    return (
        [str(p) for p in photo_files(CFG.photos.folder)]
        if CFG.robot == "guided"
        else []
    )


def person_sim_inputs(wildcards):
    """What the simulated person of round r reads: round r-1's guide (the checkpoint), shots
    and map, and the logs of its own earlier photos (where it truly took them)."""
    r = int(wildcards.r)
    prev = round_dir(r - 1)
    round_checkpoint(f"{r - 1:03d}")
    return (
        [f"{prev}/goals.json", f"{prev}/guide/index.html"]
        + [f"{prev}/sfm/{f}" for f in MODEL_FILES]
        + [f"{round_dir(k)}/capture/log.jsonl" for k in range(r)]
    )


def adaptive_capture_sections():
    """The config sections an adaptive round's capture reads (a change re-takes it)."""
    if GUIDED:
        return CFG.robot_sections()
    return (
        "exploration",
        *CFG.robot_sections(),
        "follow",
        "adaptive",
        "localize",
        "plan",
    )


def adaptive_capture_params():
    """The adaptive capture's parameters: its sections, and of `score` only the settings the
    localization gate reads (follow.min_matchable_points; scenebot/capture/predict.py): a
    change to the score's other settings re-decides the goals, never re-takes photos."""
    doc = json.loads(stage_params(*adaptive_capture_sections()))
    if not GUIDED:
        doc["score"] = {k: getattr(CFG.score, k) for k in SCORE_SETTINGS}
    return json.dumps(doc, sort_keys=True, separators=(",", ":"))


def previous_goals(wildcards):
    """Round r-1's goals.json and free space (none for round 0): the goals stage compares the
    rounds' mean view scores and free space (goals.min_score_gain, min_area_gain)."""
    r = int(wildcards.r)
    prev = f"{RESULTS}/round_{r - 1:03d}"
    return [f"{prev}/goals.json", f"{prev}/freespace.npz"] if r > 0 else []


def adaptive_logs_until(wildcards):
    """The capture logs of the adaptive rounds 1..r: the goals stage avoids goals abandoned
    there and stops a campaign stuck without photos (scenebot.goals.failures)."""
    r = int(wildcards.r)
    return (
        []
        if PERSON
        else [f"{RESULTS}/round_{k:03d}/capture/log.jsonl" for k in range(1, r + 1)]
    )


def guide_fulfilment(wildcards):
    """A guided round's fulfilment.json (rounds >= 1): the goals stage does not ask again
    for a shot no photo fulfilled (scenebot.goals.failures.unfulfilled_shots)."""
    r = int(wildcards.r)
    return [f"{round_dir(r)}/fulfilment.json"] if GUIDED and r > 0 else []


def previous_fulfilment(wildcards):
    """Round r-1's fulfilment.json (rounds >= 2 of a guided campaign): its unfulfilled shots
    are carried into round r's frame."""
    r = int(wildcards.r)
    return [f"{round_dir(r - 1)}/fulfilment.json"] if GUIDED and r > 1 else []


def person_mesh(wildcards):
    """The round's mesh for the goals stage of a person's photos (its coverage picture:
    how many photos saw each part of the surface); a robot's goals do not read it."""
    return [f"{round_dir(wildcards.r)}/mesh.ply"] if PERSON else []


def guide_shots(wildcards):
    """A guided round's shots (round r-1's goals.json): the sfm stage expects each of the
    person's new photos near one of them (sfm.person_shot_distance_m). None for round 0 and
    for a robot's rounds."""
    r = int(wildcards.r)
    return [f"{round_dir(r - 1)}/goals.json"] if GUIDED and r > 0 else []


def captures_until(wildcards):
    """The capture logs of rounds 0..r (the map of round r uses all of them)."""
    r = int(wildcards.r)
    if PHOTOS and r == 0:  # the photo files as the sfm stage reads them
        return [str(p) for p in photo_files(CFG.photos.folder)]
    return [f"{RESULTS}/round_{k:03d}/capture/log.jsonl" for k in range(r + 1)]


def options(**paths):
    """Command-line options of a stage's files, ``--name path ...`` (quoted); an empty list or
    None leaves the option out."""
    out = []
    for name, value in paths.items():
        values = [value] if isinstance(value, (str, Path)) else list(value or [])
        if values:
            out.append(
                f"--{name.replace('_', '-')} "
                + " ".join(shlex.quote(str(v)) for v in values)
            )
    return " ".join(out)


def sfm_photo_options(wildcards):
    """The sfm stage's photos: round 0 from the photo folder (``robot: photos``), else the
    capture folders of rounds 0..r."""
    if PHOTOS and int(wildcards.r) == 0:
        return options(photo_folder=CFG.photos.folder)
    logs = [Path(f) for f in captures_until(wildcards)]
    return options(capture_dirs=[f.parent for f in logs])


def image_root(scene_dir):
    """The folder the map's image names are relative to: the scene folder (results/<scene>,
    names like round_000/capture/images/r000_0000.jpg), or the photo folder."""
    return CFG.photos.folder if PHOTOS else scene_dir


def last_round_freespace(wildcards):
    """The free space of the campaign's last round (keeps the tour path off the geometry)."""
    return f"{round_dir(campaign_rounds()[-1])}/freespace.npz"


SIMULATED = CFG.robot in (
    "sim",
    "nxt-emulated",
    "person-sim",
)  # the true scene is known
# bring-your-own photos with their true cameras (evaluate.reference_cameras), and the scene
# they were taken in (evaluate.reference_world): evaluated as far as the truth given allows
REFERENCE = PHOTOS and CFG.evaluate.reference_cameras is not None
SCENE_TRUTH = SIMULATED or (REFERENCE and CFG.evaluate.reference_world)
EVALUATED = SIMULATED or REFERENCE


def fulfilments_until(wildcards):
    """Guided rounds: the fulfilment.json of rounds 1..r (the evaluation reports the shots
    fulfilled)."""
    r = int(wildcards.r) if hasattr(wildcards, "r") else last_round_index(wildcards)
    return (
        [f"{round_dir(k)}/fulfilment.json" for k in range(1, r + 1)] if GUIDED else []
    )


def observable_input(wildcards):
    """The observable surface, where the true scene is known."""
    return [f"{RESULTS}/eval/observable_surface.npz"] if SCENE_TRUTH else []


def observable_cache_option(wildcards, output):
    """`--cache-dir` of rule observable where the config sets evaluate.cache_dir (made
    absolute; '': no shared cache), else nothing: the stage then follows $SCENEBOT_CACHE or
    $XDG_CACHE_HOME. A function of the output, so that Snakemake leaves it out of the
    parameters whose change re-runs a job: where the cache lives changes no result."""
    if CFG.evaluate.cache_dir is None:
        return ""
    folder = CFG.evaluate.cache_folder()
    return f"--cache-dir {shlex.quote('' if folder is None else str(folder))}"


def reference_source(wildcards):
    """The file(s) of evaluate.reference_cameras (a file, or a COLMAP model folder)."""
    path = Path(CFG.evaluate.reference_cameras)
    return sorted(str(p) for p in path.glob("*")) if path.is_dir() else [str(path)]


def reference_input(wildcards):
    """robot: photos: the reference cameras as capture-log records (rule reference)."""
    return [f"{RESULTS}/eval/reference_cameras.jsonl"] if REFERENCE else []


def last_round_index(wildcards):
    """The campaign's last round (the one dense and the tour use)."""
    return campaign_rounds()[-1]


def captures_of_campaign(wildcards):
    """The capture logs of every round of the campaign."""
    return captures_until(SimpleNamespace(r=f"{last_round_index(wildcards):03d}"))


def evaluation_products(wildcards):
    """Every round's evaluation and the observable surface (for `rule all` or `campaign`)."""
    files = [f"{RESULTS}/eval/observable_surface.png"] if SCENE_TRUTH else []
    for r in campaign_rounds():
        files += [f"{round_dir(r)}/evaluation.json", f"{round_dir(r)}/evaluation.png"]
    files += [f"{RESULTS}/final/evaluation.json", f"{RESULTS}/final/evaluation.png"]
    if SIMULATED and CFG.evaluate.validity_candidates > 0:
        files += [
            f"{RESULTS}/final/score_validity.json",
            f"{RESULTS}/final/score_validity.png",
        ]
    return files


def validity_round(wildcards):
    """The round of the score-validity study: evaluate.validity_round, or the last round
    when the campaign stopped before it."""
    return min(CFG.evaluate.validity_round, last_round_index(wildcards))


def validity_candidates(wildcards):
    """The scored candidates and the map of the score-validity round."""
    d = round_dir(validity_round(wildcards))
    return [f"{d}/candidates.csv"] + [f"{d}/sfm/{f}" for f in MODEL_FILES]


def validity_captures(wildcards):
    """The capture logs of rounds 0..validity round (their photos and true poses)."""
    return captures_until(SimpleNamespace(r=f"{validity_round(wildcards):03d}"))


def size_suite_rules(names):
    """The sizes a profile gives the campaign's rules by name (set-resources and set-threads
    of profiles/slurm), given to each suite scene's copy too (suite_<name>_<rule>), unless the
    profile names the copy itself. Without them a suite's SLURM job asks for the
    default-resources only (10 min and 1 GB, which kill dense and baselines) and one core.
    """
    from snakemake.resources import Resources

    sizes = workflow.resource_settings.overwrite_resources
    threads = workflow.resource_settings.overwrite_threads
    prefixes = sorted((f"suite_{name}_" for name in names), key=len, reverse=True)
    for copy in list(workflow.rules):
        prefix = next((p for p in prefixes if copy.name.startswith(p)), None)
        if prefix is None:
            continue
        base = copy.name[len(prefix) :]
        if base in sizes and copy.name not in sizes:
            copy.resources.update(Resources.from_mapping(sizes[base]))
        if base in threads and copy.name not in threads:
            copy.resources["_cores"] = threads[base]
