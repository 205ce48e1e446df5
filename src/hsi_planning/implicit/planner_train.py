"""Training the shipped planner: build data (:mod:`.data_build`), train, write the checkpoint.

The checkpoint (``models/planner.pt``, written by :func:`~hsi_planning.implicit.train.save_checkpoint`,
readable with ``torch.load(weights_only=True)``) holds the network, one latent per training problem and
in ``meta``: ``prior_bank`` (:meth:`PriorBank.to_meta`), ``field_config`` (the problem's
:class:`~hsi_planning.fields.FieldConfig`), ``feature`` (blocks, condition scale), ``data_config``,
``dataset`` (counts), ``train`` (seconds, throughput, final losses, a loss curve) and ``train_seeds``.
:func:`load_planner` reads it back with the bank and field config decoded.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hsi_planning.errors import ConfigError, PlanningError
from hsi_planning.fields import FieldConfig
from hsi_planning.implicit.data_build import DataBuildConfig, PlannerData, build_planner_data
from hsi_planning.implicit.model import CHANNELS, AutoDecoderConfig
from hsi_planning.implicit.prior_bank import PriorBank
from hsi_planning.implicit.problem import (
    CONDITION_FEATURE_SCALE,
    FEATURE_BLOCKS,
    PLANNER_FIELD_CONFIG,
    TEST_SEED_START,
    TRAIN_SEEDS,
)
from hsi_planning.implicit.train import Checkpoint, TrainConfig, load_checkpoint, save_checkpoint, train

_LOG = logging.getLogger(__name__)

#: Identifies planner checkpoints (``meta["kind"]``).
PLANNER_KIND = "hsi-implicit-planner"
#: Default training of the shipped planner: a 5 × 192 decoder with 64-d latents (the issue allows a
#: network smaller than the paper's 6 × 256 when the benchmark keeps its success rate), sized to train in
#: well under an hour on 2 shared CPU cores.
PLANNER_TRAIN = TrainConfig(
    model=AutoDecoderConfig(latent_dim=64, n_layers=5, width=192, skip_layer=3),
    steps=3000,
    batch_size=16,
    points_per_sample=1024,
    lr_decay_every=1000,
    threads=1,
)


@dataclass(frozen=True)
class PlannerTrainConfig:
    """``hsi train planner``: data, training and output (YAML keys override these defaults)."""

    data: DataBuildConfig = field(default_factory=DataBuildConfig)  #: [-] what data to build
    train: TrainConfig = PLANNER_TRAIN  #: [-] auto-decoder training (its model.channels is replaced)
    channels: tuple[str, ...] = (
        CHANNELS  #: [-] fields the network predicts; ("t", "toa") = ablation without D_o
    )
    cache_dir: str = "out/cache/fields"  #: [path] field cache (relative: to the repository root)
    out: str = "models/planner.pt"  #: [path] checkpoint to write (relative: to the repository root)
    loss_curve_points: int = 100  #: [-] points of the loss curve stored in the checkpoint

    def __post_init__(self) -> None:
        chans = tuple(self.channels)
        if "t" not in chans or "toa" not in chans or list(chans) != [c for c in CHANNELS if c in chans]:
            raise ConfigError(f"channels={chans!r} must contain 't' and 'toa', in the order {list(CHANNELS)}")
        if self.loss_curve_points < 2:
            raise ConfigError(f"loss_curve_points={self.loss_curve_points} must be ≥ 2")
        object.__setattr__(self, "channels", chans)

    @property
    def train_config(self) -> TrainConfig:
        """:attr:`train` with the model's channels set to :attr:`channels`."""
        model = dataclasses.replace(self.train.model, channels=self.channels)
        return dataclasses.replace(self.train, model=model)


def quick_config(config: PlannerTrainConfig) -> PlannerTrainConfig:
    """A seconds-long variant of ``config`` (one layout, one target, right hand, tiny network, 20 steps)."""
    data = dataclasses.replace(
        config.data,
        scenes=config.data.scenes[:1],
        reshape_groups=config.data.reshape_groups[:1],
        layouts_per_group=1,
        targets_per_layout=1,
        hands=("right",),
        actions=("grasp",),
        workers=1,
    )
    tiny = dataclasses.replace(
        config.train.model, latent_dim=8, n_layers=2, width=32, skip_layer=1, channels=config.channels
    )
    train_cfg = dataclasses.replace(
        config.train, model=tiny, steps=20, batch_size=2, points_per_sample=256, lr_decay_every=10
    )
    return dataclasses.replace(config, data=data, train=train_cfg)


@dataclass(frozen=True)
class PlannerCheckpoint:
    """A loaded planner checkpoint: network + latents, the prior bank and the field parameters."""

    checkpoint: Checkpoint
    bank: PriorBank
    field_config: FieldConfig


def load_planner(path: str | Path) -> PlannerCheckpoint:
    """Read a checkpoint written by :func:`train_planner`.

    Raises:
        PlanningError: not a planner checkpoint (no prior bank), or a corrupt one.
    """
    ckpt = load_checkpoint(path)
    if ckpt.meta.get("kind") != PLANNER_KIND or "prior_bank" not in ckpt.meta:
        raise PlanningError(
            f"{path}: not a planner checkpoint (meta.kind != {PLANNER_KIND!r} or no prior bank)"
        )
    bank = PriorBank.from_meta(ckpt.meta["prior_bank"])
    if int(bank.scene_id.max()) >= ckpt.latents.shape[0]:
        raise PlanningError(
            f"{path}: prior bank refers to latent {int(bank.scene_id.max())}, only "
            f"{ckpt.latents.shape[0]} stored"
        )
    try:
        fcfg = FieldConfig(**ckpt.meta["field_config"])
    except (TypeError, ConfigError) as exc:
        raise PlanningError(f"{path}: invalid field_config in the checkpoint ({exc})") from exc
    return PlannerCheckpoint(checkpoint=ckpt, bank=bank, field_config=fcfg)


def _curve(values: np.ndarray[Any, Any], points: int) -> list[float]:
    chunks = np.array_split(np.asarray(values, dtype=np.float64), min(points, len(values)))
    return [round(float(c.mean()), 6) for c in chunks]


def train_planner(
    config: PlannerTrainConfig, root: str | Path = ".", out: str | Path | None = None, progress: bool = True
) -> dict[str, Any]:
    """Build (or load cached) data, train, write the checkpoint; returns the checkpoint's summary meta.

    Args:
        root: [path] repository root (relative scene, cache and output paths are resolved there).
        out: [path] checkpoint path overriding ``config.out``.
    """
    root = Path(root)
    out_path = Path(out) if out is not None else Path(config.out)
    out_path = out_path if out_path.is_absolute() else root / out_path
    cache = Path(config.cache_dir)
    cache = cache if cache.is_absolute() else root / cache
    t0 = time.perf_counter()
    data: PlannerData = build_planner_data(config.data, root=root, cache_dir=cache, progress=progress)
    build_s = time.perf_counter() - t0
    dataset = data.dataset.select_channels(config.channels) if config.channels != CHANNELS else data.dataset
    result = train(dataset, config.train_config, progress=progress)
    final = {k: round(float(np.mean(v[-max(1, len(v) // 20) :])), 6) for k, v in result.history.items()}
    meta: dict[str, Any] = {
        "kind": PLANNER_KIND,
        "channels": list(config.channels),
        "prior_bank": data.bank.to_meta(),
        "field_config": dataclasses.asdict(PLANNER_FIELD_CONFIG),
        "feature": {"blocks": FEATURE_BLOCKS, "condition_scale": list(CONDITION_FEATURE_SCALE)},
        "data_config": dataclasses.asdict(config.data),
        "dataset": dict(data.summary),
        "train_seeds": [TRAIN_SEEDS.start, TRAIN_SEEDS.stop - 1],
        "test_seed_start": TEST_SEED_START,
        "train": {
            "build_seconds": round(build_s, 2),
            "train_seconds": round(result.seconds, 3),
            "total_seconds": round(time.perf_counter() - t0, 2),
            "points_per_second": round(result.points_per_second, 1),
            "final_losses": final,
            "loss_curve": _curve(result.history["loss"], config.loss_curve_points),
        },
    }
    size = save_checkpoint(out_path, result.model, result.latents, config.train_config, meta)
    summary = {k: v for k, v in meta.items() if k != "prior_bank"}
    summary["checkpoint"] = str(out_path)
    summary["checkpoint_bytes"] = size
    _LOG.info("planner checkpoint %s: %.2f MB, %s", out_path, size / 1e6, meta["train"])
    return summary
