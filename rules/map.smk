# The map of each round and what it decides (paper IV.B): structure from motion in the robot's
# frame, Poisson mesh and free space, candidates scored by the rendering-quality heuristic,
# goals, and paths to them over the navigation grid.


wildcard_constraints:
    r=r"\d{3}",


rule sfm:
    input:
        code=stage_code("sfm"),
        captures=captures_until,
        shots=guide_shots,
    output:
        model=multiext(
            f"{RESULTS}/round_{{r}}/sfm/",
            "cameras.bin",
            "images.bin",
            "points3D.bin",
            "point_descriptors.npz",
        ),
        map=report(
            f"{RESULTS}/round_{{r}}/sfm/map.png",
            caption="../report/map.rst",
            category="2. Map",
            subcategory="round {r}",
        ),
        report=f"{RESULTS}/round_{{r}}/sfm/report.json",
    log:
        f"{RESULTS}/logs/round_{{r}}/sfm.log",
    benchmark:
        f"{RESULTS}/benchmarks/round_{{r}}/sfm.tsv"
    conda:
        "../envs/scenebot.yaml"
    threads: ALL_CORES
    params:
        py=PY,
        cfg=stage_params("sfm", "photos"),
        database=f"{RESULTS}/sfm_db/database.db",  # the scene's features and matches, kept
        photos=sfm_photo_options,  # the capture folders of rounds 0..r, or the photo folder
        previous=lambda w: options(  # round r-1's map, continued from where it holds one
            previous_model=[f"{round_dir(int(w.r) - 1)}/sfm"] if int(w.r) > 0 else []
        ),
        shots=lambda w, input: options(shots_json=input.shots),  # a guided round's shots
        model=lambda w, output: Path(output.report).parent,
    shell:
        "{params.py:q} -m scenebot sfm --params {params.cfg:q} --database {params.database:q} "
        "{params.photos} {params.previous} {params.shots} --model-dir {params.model:q} "
        "2> >(tee {log:q} >&2)"


rule mesh:
    input:
        code=stage_code("mesh"),
        model=expand(f"{RESULTS}/round_{{{{r}}}}/sfm/{{f}}", f=MODEL_FILES),
    output:
        mesh=f"{RESULTS}/round_{{r}}/mesh.ply",
        freespace_json=f"{RESULTS}/round_{{r}}/freespace.json",
        freespace_npz=f"{RESULTS}/round_{{r}}/freespace.npz",
        picture=report(
            f"{RESULTS}/round_{{r}}/freespace.png",
            caption="../report/freespace.rst",
            category="3. Decisions",
            subcategory="round {r}",
        ),
    log:
        f"{RESULTS}/logs/round_{{r}}/mesh.log",
    benchmark:
        f"{RESULTS}/benchmarks/round_{{r}}/mesh.tsv"
    conda:
        "../envs/scenebot.yaml"
    params:
        py=PY,
        cfg=stage_params("mesh"),
        sfm=lambda w, input: Path(input.model[0]).parent,
    shell:
        "{params.py:q} -m scenebot mesh --params {params.cfg:q} --sfm-dir {params.sfm:q} "
        "--mesh-ply {output.mesh:q} --freespace-json {output.freespace_json:q} "
        "--freespace-npz {output.freespace_npz:q} --freespace-png {output.picture:q} "
        "2> >(tee {log:q} >&2)"


rule score:
    input:
        code=stage_code("score"),
        model=expand(f"{RESULTS}/round_{{{{r}}}}/sfm/{{f}}", f=MODEL_FILES),
        mesh=f"{RESULTS}/round_{{r}}/mesh.ply",
        freespace=f"{RESULTS}/round_{{r}}/freespace.npz",
    output:
        candidates=report(
            f"{RESULTS}/round_{{r}}/candidates.csv",
            caption="../report/candidates.rst",
            category="3. Decisions",
            subcategory="round {r}",
        ),
        views=report(
            f"{RESULTS}/round_{{r}}/score_views.png",
            caption="../report/score_views.rst",
            category="3. Decisions",
            subcategory="round {r}",
        ),
    log:
        f"{RESULTS}/logs/round_{{r}}/score.log",
    benchmark:
        f"{RESULTS}/benchmarks/round_{{r}}/score.tsv"
    conda:
        "../envs/scenebot.yaml"
    threads: ALL_CORES
    params:
        py=PY,
        cfg=stage_params("score"),
        sfm=lambda w, input: Path(input.model[0]).parent,
    shell:
        "{params.py:q} -m scenebot score --params {params.cfg:q} --sfm-dir {params.sfm:q} "
        "--mesh-ply {input.mesh:q} --freespace-npz {input.freespace:q} "
        "--candidates-csv {output.candidates:q} --views-png {output.views:q} "
        "2> >(tee {log:q} >&2)"


rule goals:
    input:
        code=stage_code("goals"),
        model=expand(f"{RESULTS}/round_{{{{r}}}}/sfm/{{f}}", f=MODEL_FILES),
        candidates=f"{RESULTS}/round_{{r}}/candidates.csv",
        freespace=f"{RESULTS}/round_{{r}}/freespace.npz",
        previous=previous_goals,
        mesh=person_mesh,
        logs=adaptive_logs_until,
        fulfilment=guide_fulfilment,
    output:
        goals=f"{RESULTS}/round_{{r}}/goals.json",
        picture=report(
            f"{RESULTS}/round_{{r}}/goals.png",
            caption="../report/goals.rst",
            category="3. Decisions",
            subcategory="round {r}",
        ),
    log:
        f"{RESULTS}/logs/round_{{r}}/goals.log",
    benchmark:
        f"{RESULTS}/benchmarks/round_{{r}}/goals.tsv"
    conda:
        "../envs/scenebot.yaml"
    params:
        py=PY,
        cfg=stage_params("goals"),
        sfm=lambda w, input: Path(input.model[0]).parent,
        previous=lambda w, input: options(
            previous_goals_json=input.previous[:1],
            previous_freespace_npz=input.previous[1:],
            mesh_ply=input.mesh,
            capture_logs=input.logs,
            fulfilment_json=input.fulfilment,
        ),
    shell:
        "{params.py:q} -m scenebot goals --params {params.cfg:q} --sfm-dir {params.sfm:q} "
        "--candidates-csv {input.candidates:q} --freespace-npz {input.freespace:q} "
        "{params.previous} --goals-json {output.goals:q} --goals-png {output.picture:q} "
        "2> >(tee {log:q} >&2)"


# robot: photos: each shot advised to the person rendered from the round's photos by the tour's
# renderer (proxy: the sparse map's points), the part no photo sees in red. A rule of its own
# (round_products asks for it only for a person's photos): a robot's goals have no such file.
rule goals_preview:
    input:
        code=stage_code("goals-preview"),
        model=expand(f"{RESULTS}/round_{{{{r}}}}/sfm/{{f}}", f=MODEL_FILES),
        goals=f"{RESULTS}/round_{{r}}/goals.json",
        photos=captures_until,
    output:
        picture=report(
            f"{RESULTS}/round_{{r}}/goals_preview.png",
            caption="../report/goals_preview.rst",
            category="3. Decisions",
            subcategory="round {r}",
        ),
        tiles=f"{RESULTS}/round_{{r}}/goals_preview.npz",  # the previews, for the guide page
    log:
        f"{RESULTS}/logs/round_{{r}}/goals_preview.log",
    benchmark:
        f"{RESULTS}/benchmarks/round_{{r}}/goals_preview.tsv"
    conda:
        "../envs/scenebot.yaml"
    threads: ALL_CORES
    params:
        py=PY,
        cfg=stage_params("goals", "tour"),
        sfm=lambda w, input: Path(input.model[0]).parent,
        images=lambda w: image_root(RESULTS),
    shell:
        "{params.py:q} -m scenebot goals-preview --params {params.cfg:q} "
        "--sfm-dir {params.sfm:q} --image-dir {params.images:q} "
        "--goals-json {input.goals:q} --preview-png {output.picture:q} "
        "--preview-npz {output.tiles:q} 2> >(tee {log:q} >&2)"


# a person's photos (robot: photos, guided, person-sim): the guide page of the round (round_XXX/guide/index.html, static, every asset
# inline): the map from above and the side with the next shots as frusta, per shot its
# preview, the photo to start from and the step from there, the predicted gain; the coverage
# picture. `scenebot guide serve` shows it on a phone and takes the photos back.
# A checkpoint: the last decision of a guided round (the next round's capture waits for it).
checkpoint guide:
    input:
        code=stage_code("guide-page"),
        assets=GUIDE_ASSETS,
        model=expand(f"{RESULTS}/round_{{{{r}}}}/sfm/{{f}}", f=MODEL_FILES),
        report=f"{RESULTS}/round_{{r}}/sfm/report.json",
        goals=f"{RESULTS}/round_{{r}}/goals.json",
        previews=f"{RESULTS}/round_{{r}}/goals_preview.npz",
        coverage=f"{RESULTS}/round_{{r}}/goals.png",
        photos=captures_until,
    output:
        page=report(
            f"{RESULTS}/round_{{r}}/guide/index.html",
            caption="../report/guide.rst",
            category="3. Decisions",
            subcategory="round {r}",
        ),
    log:
        f"{RESULTS}/logs/round_{{r}}/guide.log",
    benchmark:
        f"{RESULTS}/benchmarks/round_{{r}}/guide.tsv"
    conda:
        "../envs/scenebot.yaml"
    params:
        py=PY,
        cfg=stage_params("guide"),
        sfm=lambda w, input: Path(input.model[0]).parent,
        images=lambda w: image_root(RESULTS),
    shell:
        "{params.py:q} -m scenebot guide page --params {params.cfg:q} "
        "--sfm-dir {params.sfm:q} --image-dir {params.images:q} "
        "--goals-json {input.goals:q} --preview-npz {input.previews:q} "
        "--coverage-png {input.coverage:q} --guide-html {output.page:q} "
        "2> >(tee {log:q} >&2)"


# A checkpoint: the last decision of a round. Whether the campaign goes on to another round
# depends on what the round decided, and the next round's capture waits for it.
checkpoint plan:
    input:
        code=stage_code("plan"),
        model=expand(f"{RESULTS}/round_{{{{r}}}}/sfm/{{f}}", f=MODEL_FILES),
        goals=f"{RESULTS}/round_{{r}}/goals.json",
    output:
        navgrid=f"{RESULTS}/round_{{r}}/navgrid.npz",
        paths=f"{RESULTS}/round_{{r}}/paths.json",
        picture=report(
            f"{RESULTS}/round_{{r}}/navgrid.png",
            caption="../report/navgrid.rst",
            category="3. Decisions",
            subcategory="round {r}",
        ),
    log:
        f"{RESULTS}/logs/round_{{r}}/plan.log",
    benchmark:
        f"{RESULTS}/benchmarks/round_{{r}}/plan.tsv"
    conda:
        "../envs/scenebot.yaml"
    params:
        py=PY,
        cfg=stage_params("plan", "sim"),
        sfm=lambda w, input: Path(input.model[0]).parent,
    shell:
        "{params.py:q} -m scenebot plan --params {params.cfg:q} --sfm-dir {params.sfm:q} "
        "--goals-json {input.goals:q} --navgrid-npz {output.navgrid:q} "
        "--paths-json {output.paths:q} --plot-png {output.picture:q} 2> >(tee {log:q} >&2)"


# Guided rounds (robot: guided, person-sim): which shots of the previous round's guide each
# photo of round r fulfilled (pose within guide.fulfil_*), the photos that fulfilled none or
# did not register named (they stay in the map, or out of it, as the sfm stage decided).
rule fulfilment:
    input:
        code=stage_code("guide-fulfilment"),
        model=expand(f"{RESULTS}/round_{{{{r}}}}/sfm/{{f}}", f=MODEL_FILES),
        report=f"{RESULTS}/round_{{r}}/sfm/report.json",
        previous=lambda w: [f"{round_dir(int(w.r) - 1)}/sfm/{f}" for f in MODEL_FILES],
        goals=lambda w: f"{round_dir(int(w.r) - 1)}/goals.json",
        log=f"{RESULTS}/round_{{r}}/capture/log.jsonl",
        previous_fulfilment=previous_fulfilment,
    output:
        json=f"{RESULTS}/round_{{r}}/fulfilment.json",
    log:
        f"{RESULTS}/logs/round_{{r}}/fulfilment.log",
    benchmark:
        f"{RESULTS}/benchmarks/round_{{r}}/fulfilment.tsv"
    wildcard_constraints:
        r=r"(?!000)\d{3}",
    conda:
        "../envs/scenebot.yaml"
    params:
        py=PY,
        cfg=stage_params("guide"),
        sfm=lambda w, input: Path(input.model[0]).parent,
        previous=lambda w, input: Path(input.previous[0]).parent,
        carried=lambda w, input: options(
            previous_fulfilment_json=input.previous_fulfilment
        ),
    shell:
        "{params.py:q} -m scenebot guide fulfilment --params {params.cfg:q} "
        "--sfm-dir {params.sfm:q} --previous-sfm-dir {params.previous:q} "
        "--goals-json {input.goals:q} --capture-log {input.log:q} "
        "--sfm-report {input.report:q} {params.carried} --fulfilment-json {output.json:q} "
        "2> >(tee {log:q} >&2)"
