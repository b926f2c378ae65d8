"""The dense stage's views spread over worker processes on the CPU (issue 22).

The views of each step are independent given the maps the previous step wrote: the
photometric pass of every view, then the geometric pass against the sources' photometric
maps, then the filter, then the plane fill. On the CPU, :class:`ViewPool` runs a step's views
in ``dense.num_threads`` worker processes, each with taichi on one thread: a worker runs a
whole view (kernels, numpy steps between them, reading and writing its maps), so both cores
of a small machine stay busy. Taichi's own threads would share a kernel's pixels, but not the
Python and numpy work between kernels, nor the plane fill.

A view's maps do not depend on the worker count: PatchMatch draws its random numbers from
(pixel, kernel call) counters that restart with every view
(:meth:`~scenebot.dense.patchmatch.PatchMatchSolver.estimate`), and every step reads only
what the previous step wrote. With one worker, or on a GPU, the steps run in this process.
"""

from __future__ import annotations

import contextlib
import logging
import os
import pickle
import uuid
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Any

LOG = logging.getLogger(__name__)

#: thread counts of the numeric libraries in the workers (each worker is one core's work)
_ONE_THREAD = {k: "1" for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}

#: in a worker: the shared data of the step it serves, by file (see :meth:`ViewPool.map`)
_SHARED: dict[str, Any] = {}


def cpu_cores() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def worker_count(num_threads: int, on_cpu: bool) -> int:
    """Worker processes for ``dense.num_threads`` (-1: every core); 1 (this process) on a
    GPU, whose kernels one process keeps busy."""
    if not on_cpu:
        return 1
    return cpu_cores() if num_threads <= 0 else num_threads


#: OpenBLAS's thread-count functions, by the name each build exports them under
_BLAS_THREADS = (
    ("openblas_get_num_threads", "openblas_set_num_threads"),
    ("openblas_get_num_threads64_", "openblas_set_num_threads64_"),
    ("scipy_openblas_get_num_threads64_", "scipy_openblas_set_num_threads64_"),
)


def _openblas() -> list[tuple[Callable, Callable]]:
    """(get, set) thread-count functions of the OpenBLAS libraries this process has loaded
    (Linux: from ``/proc/self/maps``; none elsewhere)."""
    import ctypes

    try:
        with open("/proc/self/maps") as fh:
            paths = {ln.split()[-1] for ln in fh if "openblas" in ln.lower() and ".so" in ln}
    except OSError:
        return []
    found = []
    for path in sorted(paths):
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for get, set_ in _BLAS_THREADS:
            if hasattr(lib, get) and hasattr(lib, set_):
                found.append((getattr(lib, get), getattr(lib, set_)))
                break
    return found


@contextlib.contextmanager
def one_blas_thread() -> Iterator[None]:
    """OpenBLAS on one thread in this process meanwhile. The stage's products are small
    ((N, 3) @ (3, 3)); OpenBLAS's threads made them 10 to 30 times slower on a busy 2-core
    machine (the workers start with one thread, :data:`_ONE_THREAD`)."""
    libs = _openblas()
    before = [get() for get, _ in libs]
    for _, set_ in libs:
        set_(1)
    try:
        yield
    finally:
        for (_, set_), n in zip(libs, before, strict=True):
            set_(n)


def _init_worker(seed: int) -> None:
    """A worker's start: taichi on the CPU with one thread, OpenCV on one thread."""
    import cv2

    from scenebot.taichi_setup import init_taichi

    cv2.setNumThreads(1)
    init_taichi("cpu", 1, seed)


def _run_shared(fn: Callable, item: Any, shared_file: str) -> Any:
    """In a worker: ``fn(item, shared)`` with the step's shared data, read once per step."""
    if shared_file not in _SHARED:
        _SHARED.clear()
        with open(shared_file, "rb") as fh:
            _SHARED[shared_file] = pickle.load(fh)
    return fn(item, _SHARED[shared_file])


@contextlib.contextmanager
def _environ(values: dict[str, str]) -> Iterator[None]:
    """``os.environ`` with ``values`` set (inherited by the workers started meanwhile)."""
    old = {k: os.environ.get(k) for k in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


class ViewPool:
    """Runs a function over views, in this process (one worker) or in worker processes.

    Args:
        workers: number of processes; 1 runs everything in this process.
        seed: taichi's random seed in the workers (``dense.patchmatch.seed``).
        scratch: folder for the files that hand a step's shared data to the workers.
    """

    def __init__(self, workers: int, seed: int, scratch: Path):
        self.workers = max(1, int(workers))
        self.seed = seed
        self.scratch = Path(scratch)
        self._executor: ProcessPoolExecutor | None = None

    def __enter__(self) -> ViewPool:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Stop the workers (they are started by the first :meth:`map`)."""
        if self._executor is not None:
            self._executor.shutdown(wait=True, cancel_futures=True)
            self._executor = None

    def _pool(self) -> ProcessPoolExecutor:
        if self._executor is None:
            import multiprocessing

            # spawn: a fork would copy this process's taichi runtime and threads
            self._executor = ProcessPoolExecutor(
                self.workers,
                mp_context=multiprocessing.get_context("spawn"),
                initializer=_init_worker,
                initargs=(self.seed,),
            )
        return self._executor

    def map(
        self,
        fn: Callable[[Any, Any], Any],
        items: Sequence,
        shared: Any = None,
        progress: str | None = None,
    ) -> list:
        """``[fn(item, shared) for item in items]``, the items spread over the workers.

        ``fn`` must be a module-level function; ``shared`` (the step's settings, planes,
        ...) goes to each worker once, through a file in ``scratch``. ``progress``: the
        label of a progress bar (none without). Exceptions are raised here, the first
        item's first.
        """
        from tqdm import tqdm

        bar = tqdm(total=len(items), desc=progress, unit="view", disable=progress is None)
        if self.workers == 1 or len(items) <= 1:
            out = []
            for item in items:
                out.append(fn(item, shared))
                bar.update()
            bar.close()
            return out
        self.scratch.mkdir(parents=True, exist_ok=True)
        shared_file = self.scratch / f".shared-{uuid.uuid4().hex}.pkl"
        with open(shared_file, "wb") as fh:
            pickle.dump(shared, fh, protocol=pickle.HIGHEST_PROTOCOL)
        try:
            with _environ(_ONE_THREAD):  # the workers start with the first tasks
                futures = [
                    self._pool().submit(_run_shared, fn, item, str(shared_file)) for item in items
                ]
            for _ in as_completed(futures):
                bar.update()
            bar.close()
            return [f.result() for f in futures]
        finally:
            shared_file.unlink(missing_ok=True)
