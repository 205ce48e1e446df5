"""Batch field computation for datasets: content-hash cache keys, .npz storage and a process pool."""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import logging
import multiprocessing
import os
import tempfile
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from tqdm import tqdm

from hsi_planning.errors import ConfigError, HsiError, PlanningError
from hsi_planning.fields.config import FieldConfig
from hsi_planning.fields.field_set import FieldSet, compute_fields
from hsi_planning.fields.grid import GridSpec
from hsi_planning.trajectory import WristTrajectory

_LOG = logging.getLogger(__name__)

#: Bumped whenever the field computation changes in a way that invalidates cached results.
FIELDS_VERSION = "fields-v1"
_ARRAYS = ("d_t", "d_o", "d_toa", "dist_t", "dist_o", "phi", "obstacle_mask", "target_mask", "goal")


@dataclass(frozen=True, eq=False)
class FieldJob:
    """The inputs of one :func:`compute_fields` call (arrays are copied).

    Attributes:
        points: (N, 3) [m] world-frame cloud.
        labels: (N,) integer label per point.
        target_labels / obstacle_labels: which labels are the target and the obstacles.
        demo: optional demonstration for the time-of-arrival field.
        config: field parameters.
        grid: optional explicit grid (default: centred on the target).
        approach_direction: optional (3,) approach side for ``config.approach_shift``.
        name: free text used in progress and error messages.
    """

    points: NDArray[np.float64]
    labels: NDArray[np.int64]
    target_labels: tuple[int, ...]
    obstacle_labels: tuple[int, ...]
    demo: WristTrajectory | None = None
    config: FieldConfig = field(default_factory=FieldConfig)
    grid: GridSpec | None = None
    approach_direction: tuple[float, float, float] | None = None
    name: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "points", np.array(self.points, dtype=np.float64, copy=True))
        object.__setattr__(self, "labels", np.array(self.labels, copy=True))
        object.__setattr__(self, "target_labels", tuple(int(v) for v in self.target_labels))
        object.__setattr__(self, "obstacle_labels", tuple(int(v) for v in self.obstacle_labels))
        if self.approach_direction is not None:
            d = np.asarray(self.approach_direction, dtype=np.float64).reshape(3)
            object.__setattr__(self, "approach_direction", (float(d[0]), float(d[1]), float(d[2])))

    def compute(self) -> FieldSet:
        """Run :func:`compute_fields` on this job."""
        return compute_fields(
            self.points,
            self.labels,
            self.target_labels,
            self.obstacle_labels,
            self.demo,
            config=self.config,
            grid=self.grid,
            approach_direction=self.approach_direction,
        )


def _hash_array(h: Any, arr: ArrayLike) -> None:
    a = np.ascontiguousarray(arr)
    h.update(f"{a.dtype.str}{a.shape}".encode())
    h.update(a.tobytes())


def fields_cache_key(job: FieldJob) -> str:
    """Hex digest (32 chars) of everything that determines the fields of ``job`` (not its name)."""
    h = hashlib.sha256(FIELDS_VERSION.encode())
    _hash_array(h, job.points)
    _hash_array(h, np.asarray(job.labels).astype(np.int64))
    h.update(repr((sorted(job.target_labels), sorted(job.obstacle_labels))).encode())
    h.update(json.dumps(dataclasses.asdict(job.config), sort_keys=True).encode())
    h.update(repr(None if job.grid is None else dataclasses.astuple(job.grid)).encode())
    h.update(repr(job.approach_direction).encode())
    if job.demo is None:
        h.update(b"no-demo")
    else:
        d = job.demo
        for arr in (d.t, d.position, d.quaternion):
            _hash_array(h, arr)
        h.update(repr((d.segment, d.contact_index)).encode())
    return h.hexdigest()[:32]


def save_fields(fields: FieldSet, path: str | Path) -> Path:
    """Write ``fields`` to a compressed .npz file (atomically: temp file, then rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    meta = {
        "version": FIELDS_VERSION,
        "grid": dataclasses.asdict(fields.grid),
        "config": dataclasses.asdict(fields.config),
    }
    arrays = {k: getattr(fields, k) for k in _ARRAYS if getattr(fields, k) is not None}
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            np.savez_compressed(fh, meta=np.array(json.dumps(meta)), **arrays)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return path


def load_fields(path: str | Path) -> FieldSet:
    """Read a file written by :func:`save_fields`.

    Raises:
        PlanningError: missing file, not a field file, or written by another field version.
    """
    path = Path(path)
    if not path.is_file():
        raise PlanningError(f"{path}: no such field file")
    try:
        with np.load(path, allow_pickle=False) as data:
            meta = json.loads(str(data["meta"]))
            arrays = {k: np.array(data[k]) for k in _ARRAYS if k in data.files}
    except (OSError, ValueError, KeyError) as exc:
        raise PlanningError(f"{path}: not a field file ({exc})") from exc
    if meta.get("version") != FIELDS_VERSION:
        raise PlanningError(f"{path}: field version {meta.get('version')!r}, expected {FIELDS_VERSION!r}")
    grid_meta = meta["grid"]
    try:
        grid = GridSpec(tuple(grid_meta["centre"]), grid_meta["size"], grid_meta["resolution"])
        config = FieldConfig(**meta["config"])
    except (ConfigError, TypeError) as exc:
        raise PlanningError(f"{path}: invalid grid or config in the file ({exc})") from exc
    return FieldSet(
        grid=grid,
        config=config,
        d_t=arrays["d_t"],
        d_o=arrays["d_o"],
        d_toa=arrays.get("d_toa"),
        dist_t=arrays["dist_t"],
        dist_o=arrays["dist_o"],
        phi=arrays.get("phi"),
        obstacle_mask=arrays["obstacle_mask"],
        target_mask=arrays["target_mask"],
        goal=arrays.get("goal"),
    )


def _run_job(job: FieldJob, cache_path: str | None) -> FieldSet:
    fields = job.compute()
    if cache_path is not None:
        save_fields(fields, cache_path)
    return fields


def compute_many(
    jobs: Sequence[FieldJob],
    workers: int = 2,
    cache_dir: str | Path | None = None,
    progress: bool = True,
    skip_errors: bool = False,
) -> list[FieldSet | None]:
    """Compute the fields of many jobs, in order, with a process pool and an optional .npz cache.

    A job whose ``<cache_dir>/<fields_cache_key(job)>.npz`` exists is loaded instead of computed; new
    results are written there. ``workers <= 1`` computes in this process.

    Args:
        jobs: the jobs.
        workers: number of worker processes (spawned).
        cache_dir: folder of cached results; None = no cache.
        progress: show a tqdm progress bar.
        skip_errors: on a job's :class:`HsiError`, log it and return None in its place instead of raising.

    Raises:
        PlanningError: (without ``skip_errors``) a job failed; the message names the job.
    """
    cache = None if cache_dir is None else Path(cache_dir)
    if cache is not None:
        cache.mkdir(parents=True, exist_ok=True)
    results: list[FieldSet | None] = [None] * len(jobs)
    todo: list[tuple[int, str | None]] = []
    for i, job in enumerate(jobs):
        target = None if cache is None else cache / f"{fields_cache_key(job)}.npz"
        if target is not None and target.is_file():
            results[i] = load_fields(target)
        else:
            todo.append((i, None if target is None else str(target)))
    bar = tqdm(total=len(jobs), initial=len(jobs) - len(todo), desc="fields", disable=not progress)

    def _finish(i: int, get: Any) -> None:
        try:
            results[i] = get()
        except Exception as exc:  # worker errors come back as their own type
            label = jobs[i].name or f"#{i}"
            if skip_errors and isinstance(exc, HsiError):
                _LOG.warning("fields of job %s failed: %s", label, exc)
            else:
                raise PlanningError(f"fields of job {label} failed: {exc}") from exc
        finally:
            bar.update(1)

    try:
        if workers <= 1 or len(todo) <= 1:
            for i, path in todo:
                _finish(i, functools.partial(_run_job, jobs[i], path))
        else:
            ctx = multiprocessing.get_context("spawn")
            with ProcessPoolExecutor(max_workers=min(workers, len(todo)), mp_context=ctx) as pool:
                futures = {pool.submit(_run_job, jobs[i], path): i for i, path in todo}
                for fut in as_completed(futures):
                    _finish(futures[fut], fut.result)
    finally:
        bar.close()
    return results
