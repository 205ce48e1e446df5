"""Training of the auto-decoder (CHOICE Eq. 8) and checkpoint I/O.

Loss per step, on a batch of B samples × P points (fields normalised by ``target_scale``):
``w_t·mean|D̂_t − D_t| + w_o·mean|D̂_o − D_o| + w_toa·mean(D̂_toa − D_toa)² + λ·mean_b ||z_b||²``.
The last term is Eq. 8's ||z_i||²/σ² written DeepSDF-style: with the data terms averaged over points,
λ plays the role of 1/σ² divided by the number of points per scene.

Network and latents have separate Adam learning rates (DeepSDF: 5e-4 / 1e-3), both decayed by
``lr_decay_factor`` every ``lr_decay_every`` steps. Runs are reproducible for a given seed and thread
count; the global torch RNG state and thread count are restored afterwards.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import pickle
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray
from tqdm import tqdm

from hsi_planning.config import from_mapping
from hsi_planning.errors import ConfigError, PlanningError
from hsi_planning.implicit.dataset import FieldDataset
from hsi_planning.implicit.model import CHANNELS, AutoDecoder, AutoDecoderConfig

_LOG = logging.getLogger(__name__)
_FORMAT = "hsi-autodecoder"
_VERSION = 1
#: Checkpoints above this size are reported (the planner ships its weights in the repository).
MAX_CHECKPOINT_BYTES = 10 * 1024 * 1024


@dataclass(frozen=True)
class TrainConfig:
    """Training of :class:`AutoDecoder` with per-scene latents (defaults: ≈ 35–40 min on 2 cores)."""

    model: AutoDecoderConfig = field(default_factory=AutoDecoderConfig)  #: [-] network architecture
    steps: int = 3000  #: [steps] optimizer steps
    batch_size: int = 16  #: [samples] training samples per step
    points_per_sample: int = 2048  #: [points] grid points drawn per sample and step
    near_share: float = 0.5  #: [-] share of points drawn from the high-D_toa pool (0 = uniform only)
    lr_net: float = 5e-4  #: [1/step] Adam learning rate of the network weights
    lr_latent: float = 1e-3  #: [1/step] Adam learning rate of the latent codes
    lr_decay_every: int = 1000  #: [steps] step interval of the learning-rate decay
    lr_decay_factor: float = 0.5  #: [-] multiplier applied to both learning rates at each decay
    latent_reg: float = 1e-4  #: [-] λ of λ·||z||² (Eq. 8's 1/σ² per point)
    latent_init_std: float = 0.05  #: [-] std of the normal initialisation of the latents
    loss_weights: tuple[float, ...] = (1.0, 1.0, 1.0)  #: [-] weights of the t, o, toa terms
    seed: int = 0  #: [-] seed of torch and numpy generators
    threads: int = 2  #: [-] torch intra-op threads during training

    def __post_init__(self) -> None:
        for name in ("steps", "batch_size", "points_per_sample", "lr_decay_every", "threads"):
            if getattr(self, name) < 1:
                raise ConfigError(f"{name}={getattr(self, name)} must be ≥ 1")
        if not 0.0 <= self.near_share <= 1.0:
            raise ConfigError(f"near_share={self.near_share} must be in [0, 1]")
        for name in ("lr_net", "lr_latent"):
            if not getattr(self, name) > 0.0:
                raise ConfigError(f"{name}={getattr(self, name)} must be > 0")
        if not 0.0 < self.lr_decay_factor <= 1.0:
            raise ConfigError(f"lr_decay_factor={self.lr_decay_factor} must be in (0, 1]")
        if self.latent_reg < 0.0 or self.latent_init_std < 0.0:
            raise ConfigError("latent_reg and latent_init_std must be ≥ 0")
        if len(self.loss_weights) != 3 or any(w < 0.0 for w in self.loss_weights):
            raise ConfigError(f"loss_weights={self.loss_weights} must be 3 values ≥ 0 for (t, o, toa)")
        if not isinstance(self.model, AutoDecoderConfig):
            raise ConfigError(f"model must be an AutoDecoderConfig, got {type(self.model).__name__}")


@dataclass
class TrainResult:
    """Outcome of :func:`train`.

    Attributes:
        model: the trained network (eval mode).
        latents: (S, latent_dim) one code per training scene.
        history: per-step arrays (steps,): "loss" (total), "reg", and one per channel ("t", "o", "toa").
        seconds: [s] wall time of the optimisation loop.
        points_per_second: [1/s] forward+backward throughput achieved.
        config: the training configuration.
    """

    model: AutoDecoder
    latents: NDArray[np.float32]
    history: dict[str, NDArray[np.float64]]
    seconds: float
    points_per_second: float
    config: TrainConfig


def field_loss(
    pred: torch.Tensor, target: torch.Tensor, channels: tuple[str, ...], weights: tuple[float, ...]
) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """Weighted Eq. 8 data term: L1 for "t" and "o", L2 for "toa".

    Args:
        pred, target: (..., C) normalised fields, columns in ``channels`` order.
        weights: weights for (t, o, toa); absent channels are ignored.

    Returns:
        (total, per-channel mean losses).
    """
    parts: dict[str, torch.Tensor] = {}
    total = pred.new_zeros(())
    for j, ch in enumerate(channels):
        diff = pred[..., j] - target[..., j]
        term = (diff * diff).mean() if ch == "toa" else diff.abs().mean()
        parts[ch] = term
        total = total + weights[CHANNELS.index(ch)] * term
    return total, parts


def train(dataset: FieldDataset, config: TrainConfig | None = None, progress: bool = True) -> TrainResult:
    """Fit the auto-decoder and one latent per scene of ``dataset`` (Eq. 8)."""
    cfg = config or TrainConfig()
    if tuple(dataset.channels) != cfg.model.channels:
        raise ConfigError(
            f"dataset channels {list(dataset.channels)} differ from model channels "
            f"{list(cfg.model.channels)}; "
            "use dataset.select_channels(...) or set model.channels"
        )
    if cfg.near_share > 0.0 and dataset.near_index is None:
        raise ConfigError("near_share > 0 needs a 'toa' channel; set near_share=0 for this dataset")
    old_threads = torch.get_num_threads()
    torch.set_num_threads(cfg.threads)
    try:
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(cfg.seed)
            return _train(dataset, cfg, progress)
    finally:
        torch.set_num_threads(old_threads)


def _train(dataset: FieldDataset, cfg: TrainConfig, progress: bool) -> TrainResult:
    rng = np.random.default_rng(cfg.seed)
    model = AutoDecoder(cfg.model)
    model.train()
    latents = torch.nn.Parameter(torch.randn(dataset.n_scenes, cfg.model.latent_dim) * cfg.latent_init_std)
    opt = torch.optim.Adam(
        [{"params": list(model.parameters()), "lr": cfg.lr_net}, {"params": [latents], "lr": cfg.lr_latent}]
    )
    sched = torch.optim.lr_scheduler.StepLR(opt, step_size=cfg.lr_decay_every, gamma=cfg.lr_decay_factor)
    scale = cfg.model.target_scale
    names = ["loss", "reg", *cfg.model.channels]
    hist = {k: np.zeros(cfg.steps) for k in names}
    bar = tqdm(range(cfg.steps), disable=not progress, desc="auto-decoder", unit="step")
    t0 = time.perf_counter()
    for step in bar:
        b = dataset.sample_batch(rng, cfg.batch_size, cfg.points_per_sample, cfg.near_share)
        z = latents[torch.from_numpy(b.scene)]
        pred = model(z, torch.from_numpy(b.cond), torch.from_numpy(b.points))
        data, parts = field_loss(
            pred, torch.from_numpy(b.targets) / scale, cfg.model.channels, cfg.loss_weights
        )
        reg = cfg.latent_reg * (z * z).sum(dim=1).mean()
        loss = data + reg
        if not torch.isfinite(loss):
            raise PlanningError(
                f"training diverged at step {step} (loss {loss.item()}); lower the learning rates"
            )
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        sched.step()
        hist["loss"][step] = loss.item()
        hist["reg"][step] = reg.item()
        for ch, v in parts.items():
            hist[ch][step] = v.item()
        if progress and step % 20 == 0:
            bar.set_postfix(loss=f"{hist['loss'][step]:.4g}")
    seconds = time.perf_counter() - t0
    pps = cfg.steps * cfg.batch_size * cfg.points_per_sample / max(seconds, 1e-9)
    _LOG.info(
        "auto-decoder trained: %d steps in %.1f s (%.0f points/s), loss %.4g -> %.4g",
        cfg.steps,
        seconds,
        pps,
        hist["loss"][0],
        hist["loss"][-1],
    )
    model.eval()
    return TrainResult(
        model=model,
        latents=latents.detach().numpy().astype(np.float32, copy=True),
        history=hist,
        seconds=seconds,
        points_per_second=pps,
        config=cfg,
    )


@dataclass
class Checkpoint:
    """A loaded checkpoint: the network (eval mode), the training latents (S, latent_dim), config, meta."""

    model: AutoDecoder
    latents: NDArray[np.float32]
    config: TrainConfig
    meta: dict[str, Any]


def _check_plain(value: Any, where: str) -> None:
    """Meta must hold only what ``torch.load(weights_only=True)`` accepts without tensors."""
    if isinstance(value, Mapping):
        for k, v in value.items():
            if not isinstance(k, str):
                raise PlanningError(f"{where}: keys must be strings, got {k!r}")
            _check_plain(v, f"{where}.{k}")
    elif isinstance(value, (list, tuple)):
        for i, v in enumerate(value):
            _check_plain(v, f"{where}[{i}]")
    elif not (value is None or isinstance(value, (str, int, float, bool))):
        raise PlanningError(
            f"{where}: {type(value).__name__} is not allowed; use str/int/float/bool/list/dict"
        )


def save_checkpoint(
    path: str | Path,
    model: AutoDecoder,
    latents: NDArray[np.float32] | torch.Tensor,
    config: TrainConfig,
    meta: Mapping[str, Any] | None = None,
) -> int:
    """Write network weights, latents (S, latent_dim), config and plain ``meta`` to ``path``.

    Returns:
        [bytes] size of the written file (a warning is logged above 10 MB).
    """
    lat = torch.as_tensor(np.asarray(latents, dtype=np.float32)).clone()
    if lat.ndim != 2 or lat.shape[1] != model.config.latent_dim:
        raise PlanningError(f"latents must be (S, {model.config.latent_dim}), got {tuple(lat.shape)}")
    meta_d = dict(meta or {})
    _check_plain(meta_d, "meta")
    cfg = dataclasses.replace(config, model=model.config)
    payload = {
        "format": _FORMAT,
        "version": _VERSION,
        "config": dataclasses.asdict(cfg),
        "state_dict": {k: v.detach().clone() for k, v in model.state_dict().items()},
        "latents": lat,
        "meta": meta_d,
    }
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    torch.save(payload, p)
    size = p.stat().st_size
    if size > MAX_CHECKPOINT_BYTES:
        _LOG.warning("checkpoint %s is %.1f MB (> 10 MB budget)", p, size / 1e6)
    return size


def load_checkpoint(path: str | Path) -> Checkpoint:
    """Read a checkpoint written by :func:`save_checkpoint` (``torch.load(weights_only=True)``)."""
    p = Path(path)
    if not p.is_file():
        raise PlanningError(f"{p}: no such checkpoint file")
    try:
        payload = torch.load(p, map_location="cpu", weights_only=True)
    except (RuntimeError, OSError, EOFError, ValueError, pickle.UnpicklingError) as exc:
        raise PlanningError(f"{p}: not a readable torch checkpoint ({exc})") from exc
    if not isinstance(payload, dict) or payload.get("format") != _FORMAT:
        raise PlanningError(f"{p}: not an {_FORMAT} checkpoint")
    if payload.get("version") != _VERSION:
        raise PlanningError(f"{p}: checkpoint version {payload.get('version')} unsupported (need {_VERSION})")
    cfg = from_mapping(TrainConfig, payload["config"], where=f"{p}:config")
    model = AutoDecoder(cfg.model)
    try:
        model.load_state_dict(payload["state_dict"])
    except RuntimeError as exc:
        raise PlanningError(f"{p}: weights do not match the stored architecture ({exc})") from exc
    model.eval()
    lat = payload["latents"].numpy().astype(np.float32, copy=True)
    if not math.isfinite(float(np.abs(lat).sum())):
        raise PlanningError(f"{p}: latents contain NaN or inf")
    return Checkpoint(model=model, latents=lat, config=cfg, meta=dict(payload["meta"]))
