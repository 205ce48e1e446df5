"""A small synthetic scene and a tiny implicit-planner checkpoint trained on it (for the planner tests).

Scene (world frame, the person at the origin facing +x): a floor, a table top at z = 0.75 m in front
with a board above it at z = 1.0 m (an open shelf: reached from the front, along −x), a 6 × 6 × 12 cm
"can" (the target) on it, a tall box beside it and a back wall. Demonstrations come from
the real human-reach model; fields from the real field code; the network is trained with the real
training loop (a tiny network, a few hundred steps: a few seconds on 2 cores).
"""

from __future__ import annotations

import atexit
import functools
import shutil
import tempfile
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from hsi_planning.demos import ObstacleField, ReachRequest, box_mesh, generate_reach
from hsi_planning.implicit import AutoDecoderConfig, FieldDataset, TrainConfig, save_checkpoint, train
from hsi_planning.implicit.data_scene import contact_pose, wrist_frame
from hsi_planning.implicit.prior_bank import PriorBank, resample_demo
from hsi_planning.implicit.problem import local_feature, make_problem, problem_fields, unit_points
from hsi_planning.perception.cloud import LabelledCloud

AXIS = np.array([-1.0, 0.0, 0.0])  #: out of the "opening": towards the person
NAMES = {0: "floor", 1: "table", 2: "can", 3: "box", 4: "wall", 5: "board"}
#: name -> (centre, size) [m] of each body's box
BOXES = {
    "table": ((0.85, 0.0, 0.725), (0.5, 0.9, 0.05)),
    "can": ((0.78, 0.0, 0.81), (0.06, 0.06, 0.12)),
    "box": ((0.85, 0.2, 0.85), (0.12, 0.12, 0.2)),
    "wall": ((1.12, 0.0, 1.0), (0.04, 0.9, 0.6)),
    "board": ((0.85, 0.0, 1.01), (0.5, 0.9, 0.02)),
}
START = {"right": (0.25, -0.25, 1.0), "left": (0.25, 0.25, 1.0)}


def _box_surface(centre: tuple[float, ...], size: tuple[float, ...], step: float) -> NDArray[np.float64]:
    c, s = np.asarray(centre), np.asarray(size)
    pts = []
    for axis in range(3):
        others = [a for a in range(3) if a != axis]
        u = np.arange(-s[others[0]] / 2, s[others[0]] / 2 + 1e-9, step)
        v = np.arange(-s[others[1]] / 2, s[others[1]] / 2 + 1e-9, step)
        uu, vv = np.meshgrid(u, v, indexing="ij")
        for sign in (-1.0, 1.0):
            p = np.zeros((uu.size, 3))
            p[:, others[0]], p[:, others[1]] = uu.ravel(), vv.ravel()
            p[:, axis] = sign * s[axis] / 2
            pts.append(p + c)
    return np.vstack(pts)


def scene_cloud(step: float = 0.01) -> LabelledCloud:
    """The labelled cloud of the synthetic scene (floor patch included)."""
    fx, fy = np.meshgrid(np.arange(0.0, 1.3, 0.03), np.arange(-0.6, 0.6, 0.03), indexing="ij")
    parts = [np.stack([fx.ravel(), fy.ravel(), np.zeros(fx.size)], axis=1)]
    labels = [np.zeros(fx.size, np.int32)]
    for lid, name in ((1, "table"), (2, "can"), (3, "box"), (4, "wall"), (5, "board")):
        pts = _box_surface(*BOXES[name], step)
        parts.append(pts)
        labels.append(np.full(len(pts), lid, np.int32))
    return LabelledCloud(np.vstack(parts), np.concatenate(labels), label_names=dict(NAMES))


def meshes() -> dict[str, object]:
    """name -> trimesh box of each body (for the human-reach model)."""
    return {name: box_mesh(c, s) for name, (c, s) in BOXES.items()}


def build_checkpoint(path: Path, steps: int = 300, seed: int = 0) -> Path:
    """Train and save the tiny checkpoint (with its prior bank) at ``path``."""
    cloud = scene_cloud()
    can = meshes()["can"]
    contact, contact_q = contact_pose(can, AXIS, 0.06)  # type: ignore[arg-type]
    obstacles = ObstacleField({k: m for k, m in meshes().items() if k != "can"})  # type: ignore[misc]
    targets, conds, feats, demos, centres = [], [], [], [], []
    for k, (hand, segment) in enumerate(
        [("right", "approach"), ("right", "leave"), ("left", "approach"), ("left", "leave")]
    ):
        demo = generate_reach(
            ReachRequest(
                start_position=np.asarray(START[hand]),
                start_quaternion=wrist_frame(np.array([1.0, 0.0, 0.0])),
                contact_position=contact,
                contact_quaternion=contact_q,
                approach_axis=-AXIS,
                hand=hand,  # type: ignore[arg-type]
                action="grasp",
                segment=segment,  # type: ignore[arg-type]
                object_name="can",
                carried_radius=0.045,
            ),
            obstacles,
            rng=np.random.default_rng([seed, k]),
        )
        problem = make_problem(
            cloud.points,
            cloud.labels,
            [2],
            hand=hand,
            action="grasp",
            segment=segment,  # type: ignore[arg-type]
            approach_axis=AXIS,
            target_name="can",
        )
        fs = problem_fields(problem, demo)
        assert fs.d_toa is not None
        targets.append(np.stack([fs.d_t, fs.d_o, fs.d_toa], axis=-1).reshape(-1, 3))
        conds.append(problem.condition_vector())
        feats.append(local_feature(fs, problem.condition_vector()))
        demos.append(demo)
        centres.append(np.asarray(fs.grid.centre))
    dataset = FieldDataset(unit_points(fs.grid), np.stack(targets), np.zeros(4, np.int64), np.stack(conds))
    config = TrainConfig(
        model=AutoDecoderConfig(latent_dim=8, n_layers=3, width=64, skip_layer=-1),
        steps=steps,
        batch_size=4,
        points_per_sample=512,
        lr_net=2e-3,
        lr_latent=2e-3,
        lr_decay_every=max(1, steps // 2),
        seed=seed,
        threads=2,
    )
    result = train(dataset, config, progress=False)
    res = [resample_demo(d, 40) for d in demos]
    bank = PriorBank(
        features=np.stack(feats),
        cond=np.stack(conds),
        scene_id=np.zeros(4, np.int64),
        grid_centre=np.stack(centres),
        target_centre=np.zeros((4, 3)),
        approach_axis=np.tile(AXIS, (4, 1)),
        t=np.stack([r[0] for r in res]),
        position=np.stack([r[1] - c for r, c in zip(res, centres, strict=True)]),
        quaternion=np.stack([r[2] for r in res]),
        contact_index=np.array([39 if d.segment == "approach" else 0 for d in demos]),
        layout=("synthetic",) * 4,
        target=("can",) * 4,
    )
    save_checkpoint(path, result.model, result.latents, result.config, {"prior_bank": bank.to_meta()})
    return path


@functools.lru_cache(maxsize=1)
def shared_checkpoint() -> Path:
    """The tiny checkpoint, trained once per test process (removed at exit)."""
    folder = Path(tempfile.mkdtemp(prefix="hsi_tiny_planner_"))
    atexit.register(shutil.rmtree, folder, True)
    return build_checkpoint(folder / "tiny.pt", steps=100)
