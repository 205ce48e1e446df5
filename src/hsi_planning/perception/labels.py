"""Label ids of MuJoCo geoms: body names (the scene's label names) mapped to label ids.

A geom takes the label of its body; a body missing from the mapping inherits its nearest mapped
ancestor (e.g. a handle sub-body); a geom of the world body is looked up by its own name (``floor``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from hsi_planning.perception.cloud import UNLABELLED
from hsi_planning.perception.view import NO_GEOM

if TYPE_CHECKING:
    import mujoco

    from hsi_planning.scene import LabelTable


def geom_labels(model: mujoco.MjModel, labels: Mapping[str, int], keep_unlabelled: bool) -> NDArray[np.int32]:
    """(ngeom,) label id of every geom: body (or nearest mapped ancestor) name -> id; a geom of no
    mapped body gets -1 with ``keep_unlabelled``, else ``NO_GEOM`` (dropped like background)."""
    import mujoco

    out = np.full(model.ngeom, UNLABELLED if keep_unlabelled else NO_GEOM, np.int32)
    for g in range(model.ngeom):
        body = int(model.geom_bodyid[g])
        while body != 0:
            name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, body)
            if name is not None and name in labels:
                out[g] = labels[name]
                break
            body = int(model.body_parentid[body])
        else:
            name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g)
            if name is not None and name in labels:
                out[g] = labels[name]
    return out


def body_labels(model: mujoco.MjModel) -> tuple[dict[str, int], dict[int, str]]:
    """Default label mapping: every named body (world excluded) gets its body id as label."""
    import mujoco

    names = {b: mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b) for b in range(1, model.nbody)}
    return {n: b for b, n in names.items() if n}, {b: n for b, n in names.items() if n}


def label_maps(table: LabelTable) -> tuple[dict[str, int], dict[int, str], dict[int, str]]:
    """(name -> id, id -> name, id -> semantic class) of a scene label table."""
    return (
        {lab.name: lab.id for lab in table},
        {lab.id: lab.name for lab in table},
        {lab.id: lab.semantic_class for lab in table},
    )
