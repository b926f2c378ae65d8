"""Synthetic scenes with known geometry, for the tests and the benchmarks (not the pipeline).

No stage imports this package; it sits above the stages, beside the tests. It lives in the
package (rather than under ``tests/``) because ``benchmarks/`` builds its scenes from it at run
time, also on a machine where only the package is installed:

- ``sfm``: a box room photographed by a robot doing round-0 circles (photos, capture log,
  true poses), for the sfm stage (``benchmarks/bench_sfm.py``).
- ``score``: box rooms as triangle meshes with source cameras, for the mesh, score and goals
  stages (``benchmarks/bench_score.py``).
- ``dense``: ray-cast views with known depth built into a COLMAP model, for the dense stage
  (``benchmarks/bench_dense.py``).

Fixtures only the tests use live in ``tests/fixtures/``.
"""
