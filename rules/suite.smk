# The scene suite (`snakemake --cores 2 suite`): one set of settings measured on many scenes.
# Each scene of `suite.scenes` is this workflow again, as a Snakemake module with the
# scene's config (scenebot/evaluate/suite.py: the workflow's config with the scene's world,
# `scene: suite/<name>`), so its rules are the campaign's own, renamed suite_<name>_<rule>,
# writing results/suite/<name>/; the suite's report waits for every scene's final evaluation
# and baselines: one DAG. A scene's own config has no suite scenes (no recursion).
from scenebot.evaluate.suite import RESULTS as SUITE_RESULTS
from scenebot.evaluate.suite import scene_configs, scene_files

SUITE = scene_configs(config, CFG.suite)  # name -> its campaign's config
try:
    for SUITE_NAME, SUITE_CONFIG in SUITE.items():
        validate_config(SUITE_CONFIG, f"suite scene {SUITE_NAME} (suite.scenes)")
except ConfigError as exc:
    raise WorkflowError(str(exc)) from None


for SUITE_NAME, SUITE_CONFIG in SUITE.items():
    SUITE_MODULE = f"suite_{SUITE_NAME}_"

    module:
        name: SUITE_MODULE
        snakefile:
            "../Snakefile"
        config:
            SUITE_CONFIG

    use rule * from SUITE_MODULE exclude all, suite, suite_report as SUITE_MODULE*


# the profile's sizes of each campaign rule for the scenes' copies (rules/common.smk)
size_suite_rules(SUITE)


rule suite:
    input:
        f"{SUITE_RESULTS}/suite.json",
        f"{SUITE_RESULTS}/suite.md",
        f"{SUITE_RESULTS}/suite.png",
    localrule: True


# Per scene its final evaluation and its baselines (random exploration and the frontier
# chooser at the campaign's photo budget), summed up: the median and the worst scene.
rule suite_report:
    input:
        code=stage_code("suite-report"),
        evaluations=scene_files(SUITE, "final/evaluation.json"),
        baselines=scene_files(SUITE, "baselines/baselines.json"),
    output:
        json=f"{SUITE_RESULTS}/suite.json",
        md=f"{SUITE_RESULTS}/suite.md",
        png=report(
            f"{SUITE_RESULTS}/suite.png",
            caption="../report/suite.rst",
            category="8. Suite",
        ),
    log:
        f"{SUITE_RESULTS}/logs/suite_report.log",
    benchmark:
        f"{SUITE_RESULTS}/benchmarks/suite_report.tsv"
    localrule: True
    conda:
        "../envs/scenebot.yaml"
    params:
        py=PY,
        names=list(SUITE),
    shell:
        "{params.py:q} -m scenebot suite-report --names {params.names:q} "
        "--evaluations {input.evaluations:q} --baselines {input.baselines:q} "
        "--suite-json {output.json:q} --suite-md {output.md:q} --suite-png {output.png:q} "
        "2> >(tee {log:q} >&2)"
