# The products of the campaign: dense multi-view stereo on the last round's map.


rule dense:
    input:
        code=stage_code("dense"),
        model=expand(f"{RESULTS}/round_{last_round()}/sfm/{{f}}", f=MODEL_FILES),
    output:
        fused=f"{RESULTS}/final/dense/fused.ply",
    log:
        f"{RESULTS}/logs/dense.log",
    benchmark:
        f"{RESULTS}/benchmarks/dense.tsv"
    conda:
        "../envs/scenebot.yaml"
    threads: workflow.cores
    params:
        py=PY,
        cfg=stage_params("dense"),
        sparse=lambda w, input: Path(input.model[0]).parent,
        images=lambda w, input: image_root(input),
        out=lambda w, output: Path(output.fused).parent,
    shell:
        "{params.py:q} -m scenebot dense --params {params.cfg:q} --sparse {params.sparse:q} "
        "--images {params.images:q} --out {params.out:q} 2> >(tee {log:q} >&2)"
