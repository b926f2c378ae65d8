# Evaluation against the simulator's truth (paper V.B and beyond): per round and for the
# campaign's result. Simulated robots only; the truth is read here and by no decision.


# The observable surface of the true scene: computed once per scene and settings (the .npz
# records its key: the geometry and the settings), drawn top-down in the .png. A copy waits
# in the cache shared by campaigns (evaluate.cache_dir, named by the key's hash) for the next
# campaign of the scene (the suite's baselines, the tests); the log says whether it came
# from there. The cache folder is neither input nor output, and no parameter that re-runs.
rule observable:
    input:
        code=stage_code("observable"),
    output:
        npz=f"{RESULTS}/eval/observable_surface.npz",
        png=report(
            f"{RESULTS}/eval/observable_surface.png",
            caption="../report/observable_surface.rst",
            category="7. Evaluation",
            subcategory="truth",
        ),
    log:
        f"{RESULTS}/logs/observable.log",
    benchmark:
        f"{RESULTS}/benchmarks/observable.tsv"
    conda:
        "../envs/scenebot.yaml"
    params:
        py=PY,
        cfg=stage_params("world", "sim", "evaluate"),
        cache=observable_cache_option,
    shell:
        "{params.py:q} -m scenebot observable --params {params.cfg:q} {params.cache} "
        "--out {output.npz:q} --png {output.png:q} 2> >(tee {log:q} >&2)"


# robot: photos with evaluate.reference_cameras: the photos' true cameras (a Middlebury
# *_par.txt, a COLMAP model or a capture log) as capture-log records the evaluation reads.
rule reference:
    input:
        code=stage_code("reference"),
        cameras=reference_source,
    output:
        f"{RESULTS}/eval/reference_cameras.jsonl",
    log:
        f"{RESULTS}/logs/reference.log",
    conda:
        "../envs/scenebot.yaml"
    params:
        py=PY,
        cfg=stage_params("evaluate"),
    shell:
        "{params.py:q} -m scenebot reference --params {params.cfg:q} --out {output:q} "
        "2> >(tee {log:q} >&2)"


# One round's figures: photos per round, goals reached, SfM and localization accuracy. The
# round does not wait for the campaign's end; the dense cloud is evaluated by evaluate_final.
rule evaluate:
    input:
        code=stage_code("evaluate"),
        model=expand(f"{RESULTS}/round_{{{{r}}}}/sfm/{{f}}", f=MODEL_FILES),
        captures=captures_until,
        reference=reference_input,
        fulfilment=fulfilments_until,
    output:
        json=f"{RESULTS}/round_{{r}}/evaluation.json",
        png=report(
            f"{RESULTS}/round_{{r}}/evaluation.png",
            caption="../report/evaluation.rst",
            category="7. Evaluation",
            subcategory="round {r}",
        ),
    log:
        f"{RESULTS}/logs/round_{{r}}/evaluate.log",
    benchmark:
        f"{RESULTS}/benchmarks/round_{{r}}/evaluate.tsv"
    conda:
        "../envs/scenebot.yaml"
    params:
        py=PY,
        cfg=stage_params("world", "sim", "evaluate"),
        scene_dir=lambda w, output: Path(output.json).parents[1],
        reference=lambda w, input: options(reference=input.reference),
    shell:
        "{params.py:q} -m scenebot evaluate --params {params.cfg:q} "
        "--scene-dir {params.scene_dir:q} --round {wildcards.r} --out {output.json:q} "
        "{params.reference} 2> >(tee {log:q} >&2)"


# The campaign's result: the last round's figures plus the dense cloud's accuracy and
# completeness at 1, 2, 5 cm against the observable surface.
rule evaluate_final:
    input:
        code=stage_code("evaluate"),
        model=last_round_model,
        captures=captures_of_campaign,
        observable=observable_input,
        reference=reference_input,
        fulfilment=fulfilments_until,
        dense=f"{RESULTS}/final/dense/fused.ply",
    output:
        json=f"{RESULTS}/final/evaluation.json",
        png=report(
            f"{RESULTS}/final/evaluation.png",
            caption="../report/evaluation_final.rst",
            category="7. Evaluation",
            subcategory="final",
        ),
    log:
        f"{RESULTS}/logs/evaluate_final.log",
    benchmark:
        f"{RESULTS}/benchmarks/evaluate_final.tsv"
    priority: 1
    conda:
        "../envs/scenebot.yaml"
    params:
        py=PY,
        cfg=stage_params("world", "sim", "evaluate"),
        scene_dir=lambda w, output: Path(output.json).parents[1],
        round=last_round_index,
        dense=lambda w, input: f"--dense {input.dense!r}" if EVALUATED else "",
        reference=lambda w, input: options(reference=input.reference),
        observable=lambda w, input: (
            f"--observable {input.observable[0]!r}" if input.observable else ""
        ),
    shell:
        "{params.py:q} -m scenebot evaluate --params {params.cfg:q} "
        "--scene-dir {params.scene_dir:q} --round {params.round} {params.dense} "
        "{params.observable} {params.reference} --out {output.json:q} "
        "2> >(tee {log:q} >&2)"


# `snakemake --cores 2 evaluation`: evaluate every round of the campaign.
rule evaluation:
    input:
        evaluation_products,
    localrule: True


# Score validity (paper IV.B's key claim, tested): random scored candidates of one round
# (evaluate.validity_round, default 0) rendered by ULR from that round's photos and by the
# simulator from the truth; Spearman's rho between the heuristic score and PSNR.
# One core: it runs beside the final evaluation (see rule proxy).
rule validity:
    input:
        code=stage_code("validity"),
        candidates=validity_candidates,
        captures=validity_captures,
        proxy=f"{RESULTS}/final/tour/proxy.npz",
        dense_model=last_round_model,
    output:
        json=f"{RESULTS}/final/score_validity.json",
        png=report(
            f"{RESULTS}/final/score_validity.png",
            caption="../report/score_validity.rst",
            category="7. Evaluation",
            subcategory="final",
        ),
    log:
        f"{RESULTS}/logs/validity.log",
    benchmark:
        f"{RESULTS}/benchmarks/validity.tsv"
    priority: 1
    conda:
        "../envs/scenebot.yaml"
    params:
        py=PY,
        cfg=stage_params("world", "sim", "evaluate", "tour", "goals"),
        scene_dir=lambda w, output: Path(output.json).parents[1],
        round=validity_round,
        dense_round=last_round_index,
    shell:
        "{params.py:q} -m scenebot validity --params {params.cfg:q} "
        "--scene-dir {params.scene_dir:q} --round {params.round} --dense {input.proxy:q} "
        "--dense-round {params.dense_round} --out {output.json:q} 2> >(tee {log:q} >&2)"


# `snakemake --cores 2 baselines` (on demand: two more campaigns): random exploration only
# and the frontier chooser (`suite.baselines`: which of them) at the campaign's photo
# budget, each a full campaign in results/{scene}/baselines/<name>/, compared by coverage per
# photo count and dense completeness against the truth (`python -m scenebot baselines
# --replot-only` redraws them from the campaigns already run).
rule baselines:
    input:
        code=stage_code("baselines"),
        final=f"{RESULTS}/final/evaluation.json",
        campaign=f"{RESULTS}/campaign.json",
    output:
        json=f"{RESULTS}/baselines/baselines.json",
        png=report(
            f"{RESULTS}/baselines/baselines.png",
            caption="../report/baselines.rst",
            category="7. Evaluation",
            subcategory="baselines",
        ),
    log:
        f"{RESULTS}/logs/baselines.log",
    benchmark:
        f"{RESULTS}/benchmarks/baselines.tsv"
    conda:
        "../envs/scenebot.yaml"
    threads: ALL_CORES
    params:
        py=PY,
        campaign=json.dumps(config),
        scene_dir=lambda w, input: Path(input.campaign).parent,
        methods=",".join(CFG.suite.baselines),
    shell:
        "{params.py:q} -m scenebot baselines --campaign {params.campaign:q} "
        "--scene-dir {params.scene_dir:q} --methods {params.methods:q} --cores {threads} "
        "--out {output.json:q} 2> >(tee {log:q} >&2)"
