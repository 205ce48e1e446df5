"""Ground-truth labels: one label per MuJoCo body, ids dense from 0 (0 = floor), deterministic.

The label name is the body name (``cabinet1``, ``cabinet1/door1``, ``mug1``, ``floor``), which is the
contract with perception: a rendered pixel of body ``B`` carries the id of label ``B``.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Literal

from hsi_planning.errors import SceneError
from hsi_planning.scene.model import scene_bodies
from hsi_planning.scene.spec import SceneSpec

LabelKind = Literal["object", "furniture", "floor"]


@dataclass(frozen=True)
class Label:
    """One label: ``parent`` is the furniture name for furniture parts, else None."""

    id: int
    name: str
    semantic_class: str  #: e.g. "mug", "cabinet_door", "drawer", "shelf_board", "counter", "floor"
    kind: LabelKind
    parent: str | None


@dataclass(frozen=True)
class LabelTable:
    """All labels of a scene in id order."""

    labels: tuple[Label, ...]

    def __post_init__(self) -> None:
        if [lab.id for lab in self.labels] != list(range(len(self.labels))):
            raise SceneError("label ids must be dense from 0 in order")
        if len({lab.name for lab in self.labels}) != len(self.labels):
            raise SceneError("label names must be unique")

    def __len__(self) -> int:
        return len(self.labels)

    def __iter__(self) -> Iterator[Label]:
        return iter(self.labels)

    @property
    def names(self) -> tuple[str, ...]:
        """Label names in id order."""
        return tuple(lab.name for lab in self.labels)

    def by_name(self, name: str) -> Label:
        """The label called ``name``; :class:`SceneError` lists the valid names otherwise."""
        for lab in self.labels:
            if lab.name == name:
                return lab
        raise SceneError(f"no label {name!r}; valid: {list(self.names)}")

    def by_id(self, label_id: int) -> Label:
        """The label with id ``label_id``; :class:`SceneError` gives the valid range otherwise."""
        if not 0 <= label_id < len(self.labels):
            raise SceneError(f"no label id {label_id}; valid: 0..{len(self.labels) - 1}")
        return self.labels[label_id]


def scene_labels(spec: SceneSpec) -> LabelTable:
    """The label table of a scene: floor, furniture bodies (spec order), objects (spec order)."""
    bodies = scene_bodies(spec)
    return LabelTable(
        tuple(Label(i, b.name, b.semantic_class, b.kind, b.parent) for i, b in enumerate(bodies))
    )
