# The virtual tour on the last round's map: unstructured lumigraph frames along a tour path,
# tour.mp4 and a static web viewer (final/tour/index.html, works from file://).


# The dense cloud prepared for rendering once (outliers dropped, splats sized; tens of
# seconds for a campaign's millions of points): the tour and the score validity load it.
# After the dense stage the proxy goes first (priority 2), on both cores; then the final
# evaluation and the score validity (priority 1, one core each) side by side; then the tour.
rule proxy:
    input:
        code=stage_code("proxy"),
        fused=f"{RESULTS}/final/dense/fused.ply",
    output:
        proxy=f"{RESULTS}/final/tour/proxy.npz",
    log:
        f"{RESULTS}/logs/proxy.log",
    benchmark:
        f"{RESULTS}/benchmarks/proxy.tsv"
    priority: 2
    conda:
        "../envs/scenebot.yaml"
    threads: ALL_CORES
    params:
        py=PY,
        cfg=stage_params("tour"),
    shell:
        "{params.py:q} -m scenebot proxy --params {params.cfg:q} --dense {input.fused:q} "
        "--out {output.proxy:q} 2> >(tee {log:q} >&2)"


rule tour:
    input:
        code=stage_code("tour"),
        model=last_round_model,
        proxy=f"{RESULTS}/final/tour/proxy.npz",
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
        "--images {params.images:q} --dense {input.proxy:q} --freespace {input.freespace:q} "
        "--out {params.out:q} 2> >(tee {log:q} >&2)"
