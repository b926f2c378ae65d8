# Round 0: random exploration with the configured robot (paper IV.A).
# Photos are data: a capture re-runs when its settings change, not when code changes (re-take
# on purpose with --forcerun); a re-run moves an earlier attempt to capture/superseded/.


rule capture_round0:
    input:
        photos=round0_photos,  # robot: guided: the person's folder
    output:
        log=f"{RESULTS}/round_000/capture/log.jsonl",
        trajectory=report(
            f"{RESULTS}/round_000/capture/trajectory.png",
            caption="../report/trajectory_round0.rst",
            category="1. Capture",
            subcategory="round 000",
        ),
    log:
        f"{RESULTS}/logs/capture_round0.log",
    benchmark:
        f"{RESULTS}/benchmarks/capture_round0.tsv"
    localrule: True
    conda:
        "../envs/scenebot.yaml"
    resources:
        robot=1,
    params:
        py=PY,
        cfg=stage_params("exploration", *CFG.robot_sections()),
        out=lambda w, output: Path(output.log).parent,
    shell:
        "{params.py:q} -m scenebot capture --params {params.cfg:q} --out {params.out:q} "
        "2> >(tee {log:q} >&2)"


# Rounds >= 1: drive to the previous round's goals, localizing visually, and take photos there;
# a guided round (robot: guided, person-sim) takes in the photos of its inbox instead.
rule capture_adaptive:
    input:
        previous=previous_round,
    output:
        log=f"{RESULTS}/round_{{r}}/capture/log.jsonl",
        trajectory=report(
            f"{RESULTS}/round_{{r}}/capture/trajectory.png",
            caption="../report/trajectory.rst",
            category="1. Capture",
            subcategory="round {r}",
        ),
    log:
        f"{RESULTS}/logs/round_{{r}}/capture.log",
    benchmark:
        f"{RESULTS}/benchmarks/round_{{r}}/capture.tsv"
    wildcard_constraints:
        r=r"(?!000)\d{3}",
    localrule: True
    conda:
        "../envs/scenebot.yaml"
    resources:
        robot=1,
    params:
        py=PY,
        cfg=adaptive_capture_params(),
        out=lambda w, output: Path(output.log).parent,
        previous=lambda w: round_dir(int(w.r) - 1),
    shell:
        "{params.py:q} -m scenebot capture --params {params.cfg:q} --out {params.out:q} "
        "--round {wildcards.r} --previous {params.previous:q} 2> >(tee {log:q} >&2)"


# robot: person-sim: the simulated person walks to the shots of round r-1's guide and puts its
# photos in round r's inbox, as a person would (then capture_adaptive takes them in).
rule person_sim:
    input:
        previous=person_sim_inputs,
    output:
        f"{RESULTS}/round_{{r}}/capture/inbox/person-sim.jsonl",
    log:
        f"{RESULTS}/logs/round_{{r}}/person_sim.log",
    benchmark:
        f"{RESULTS}/benchmarks/round_{{r}}/person_sim.tsv"
    wildcard_constraints:
        r=r"(?!000)\d{3}",
    localrule: True
    conda:
        "../envs/scenebot.yaml"
    resources:
        robot=1,
    params:
        py=PY,
        cfg=stage_params(*CFG.robot_sections()),
        scene_dir=lambda w, output: Path(output[0]).parents[3],
    shell:
        "{params.py:q} -m scenebot person-sim --params {params.cfg:q} "
        "--scene-dir {params.scene_dir:q} --round {wildcards.r} 2> >(tee {log:q} >&2)"
