# Round 0: random exploration with the configured robot (paper IV.A).
# Photos are never deleted: a re-run moves an earlier attempt to capture/superseded/.


rule capture_round0:
    input:
        code=stage_code("capture"),
    output:
        log=f"{RESULTS}/round_000/capture/log.jsonl",
        trajectory=f"{RESULTS}/round_000/capture/trajectory.png",
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
        cfg=stage_params("world", "sim", "exploration", "nxt", "nxt_emulator"),
        out=lambda w, output: Path(output.log).parent,
    shell:
        "{params.py:q} -m scenebot capture --params {params.cfg:q} --out {params.out:q} "
        "2> >(tee {log:q} >&2)"
