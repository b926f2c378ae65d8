# The virtual tour on the last round's map: unstructured lumigraph frames along a tour path,
# tour.mp4 and a static web viewer (final/tour/index.html, works from file://).


rule tour:
    input:
        code=stage_code("tour"),
        model=last_round_model,
        fused=f"{RESULTS}/final/dense/fused.ply",
        freespace=last_round_freespace,
    output:
        video=report(
            f"{RESULTS}/final/tour/tour.mp4",
            caption="../report/tour.rst",
            category="6. Tour",
        ),
        index=f"{RESULTS}/final/tour/index.html",
        data=f"{RESULTS}/final/tour/tour_data.js",
        summary=f"{RESULTS}/final/tour/tour_summary.json",
    log:
        f"{RESULTS}/logs/tour.log",
    benchmark:
        f"{RESULTS}/benchmarks/tour.tsv"
    conda:
        "../envs/scenebot.yaml"
    threads: ALL_CORES
    params:
        py=PY,
        cfg=stage_params("tour"),
        sparse=lambda w, input: Path(input.model[0]).parent,
        images=lambda w, output: image_root(Path(output.index).parents[2]),
        out=lambda w, output: Path(output.index).parent,
    shell:
        "{params.py:q} -m scenebot tour --params {params.cfg:q} --sparse {params.sparse:q} "
        "--images {params.images:q} --dense {input.fused:q} --freespace {input.freespace:q} "
        "--out {params.out:q} 2> >(tee {log:q} >&2)"
