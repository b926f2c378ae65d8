# scenebot: autonomous scene capture, as a Snakemake workflow.
# This file is the table of contents; every decision lives in the scenebot package.
#   snakemake --cores 2                         the default campaign (config.yaml)
#   snakemake --cores 2 --configfile=my.yaml    another campaign (targets before --configfile)
from snakemake.utils import min_version

min_version("9.0")


configfile: "config.yaml"


report: "report/workflow.rst"


include: "rules/common.smk"
include: "rules/capture.smk"
include: "rules/map.smk"
include: "rules/final.smk"
include: "rules/tour.smk"
include: "rules/evaluate.smk"
include: "rules/suite.smk"


rule all:
    default_target: True
    input:
        campaign_targets,
