# The products of the campaign: its summary, and dense multi-view stereo on the last round's map.


rule campaign:
    input:
        code=stage_code("campaign"),
        rounds=round_products,
    output:
        summary=report(
            f"{RESULTS}/campaign.json",
            caption="../report/campaign_json.rst",
            category="4. Campaign",
        ),
        picture=report(
            f"{RESULTS}/campaign.png",
            caption="../report/campaign.rst",
            category="4. Campaign",
        ),
    log:
        f"{RESULTS}/logs/campaign.log",
    conda:
        "../envs/scenebot.yaml"
    params:
        py=PY,
        cfg=stage_params("goals", "max_rounds"),
        rounds=lambda w: ",".join(str(r) for r in campaign_rounds()),
        scene_dir=lambda w, output: Path(output.summary).parent,
    shell:
        "{params.py:q} -m scenebot campaign --params {params.cfg:q} --scene-dir "
        "{params.scene_dir:q} --rounds {params.rounds} --out {output.summary:q} "
        "2> >(tee {log:q} >&2)"


rule dense:
    input:
        code=stage_code("dense"),
        model=last_round_model,
    output:
        fused=f"{RESULTS}/final/dense/fused.ply",
        views=report(
            f"{RESULTS}/final/dense/fused_views.png",
            caption="../report/dense_views.rst",
            category="5. Dense model",
        ),
        mosaic=report(
            f"{RESULTS}/final/dense/depth_normal_mosaic.png",
            caption="../report/dense_mosaic.rst",
            category="5. Dense model",
        ),
        planes=report(
            f"{RESULTS}/final/dense/planes.png",
            caption="../report/dense_planes.rst",
            category="5. Dense model",
        ),
    log:
        f"{RESULTS}/logs/dense.log",
    benchmark:
        f"{RESULTS}/benchmarks/dense.tsv"
    conda:
        "../envs/scenebot.yaml"
    threads: ALL_CORES
    params:
        py=PY,
        cfg=stage_params("dense"),
        sparse=lambda w, input: Path(input.model[0]).parent,
        images=lambda w, output: image_root(Path(output.fused).parents[2]),
        out=lambda w, output: Path(output.fused).parent,
    shell:
        "{params.py:q} -m scenebot dense --params {params.cfg:q} --sparse {params.sparse:q} "
        "--images {params.images:q} --out {params.out:q} 2> >(tee {log:q} >&2)"


# Where the campaign's time went, from the benchmark file Snakemake writes for every job.
rule timing:
    input:
        code=stage_code("timing"),
        products=timed_products,
    output:
        json=f"{RESULTS}/timing.json",
        png=report(
            f"{RESULTS}/timing.png",
            caption="../report/timing.rst",
            category="4. Campaign",
        ),
    log:
        f"{RESULTS}/logs/timing.log",
    localrule: True
    conda:
        "../envs/scenebot.yaml"
    params:
        py=PY,
        benchmarks=f"{RESULTS}/benchmarks",
    shell:
        "{params.py:q} -m scenebot timing --benchmarks {params.benchmarks:q} "
        "--out {output.json:q} --png {output.png:q} 2> >(tee {log:q} >&2)"
