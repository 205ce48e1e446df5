"""Runtime use of the trained auto-decoder: latent optimisation (CHOICE Eq. 9), warm start, prediction.

At planning time the network is frozen and only the scene code z is optimised so that the decoder
reproduces the fields observable from the cloud — D_t and D_o on the object-centric grid E_t — and the
time-of-arrival field on the few points where it is known: zero inside obstacles and the last 5 cm of
the matched prior trajectory τ_prior with its known remaining time. Eq. 9 (sums over points):

``Σ_{x∈E_t} (w_t|D̂_t − D_t| + w_o|D̂_o − D_o|) + γ·Σ_{x∈X_prior} w_toa(D̂_toa − D_toa)² + λ||z||²``,
γ = N(E_t)/N(X_prior), so both data sets weigh the same in total. Divided by N(E_t) this is
``mean_grid(...) + w_toa·mean_prior(...) + λ'||z||²``, which is what is minimised on random subsets.
All field values passed in and returned are in physical units (inverse distance [1/m] or inverse
remaining time [1/s]); points are in [-1, 1] grid-local coordinates (``model.to_unit_cube``).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np
import torch
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from hsi_planning.errors import ConfigError, PlanningError
from hsi_planning.implicit.model import COND_DIM, AutoDecoder

_LOG = logging.getLogger(__name__)


@dataclass(frozen=True)
class LatentFitConfig:
    """Latent optimisation at planning time (Eq. 9)."""

    steps: int = 100  #: [steps] Adam iterations on z
    lr: float = 5e-3  #: [1/step] Adam learning rate of z
    points_per_step: int = 4096  #: [points] random grid points per step; 0 = the whole grid every step
    latent_reg: float = 1e-4  #: [-] λ of λ·||z||² (same meaning as in training)
    loss_weights: tuple[float, ...] = (1.0, 1.0, 1.0)  #: [-] weights of the t, o, toa terms
    seed: int = 0  #: [-] seed of the point subsampling
    threads: int = 0  #: [-] torch threads during the fit; 0 = leave the current setting

    def __post_init__(self) -> None:
        if self.steps < 1:
            raise ConfigError(f"steps={self.steps} must be ≥ 1")
        if not self.lr > 0.0:
            raise ConfigError(f"lr={self.lr} must be > 0")
        if self.points_per_step < 0 or self.threads < 0 or self.latent_reg < 0.0:
            raise ConfigError("points_per_step, threads and latent_reg must be ≥ 0")
        if len(self.loss_weights) != 3 or any(w < 0.0 for w in self.loss_weights):
            raise ConfigError(f"loss_weights={self.loss_weights} must be 3 values ≥ 0 for (t, o, toa)")


@dataclass(frozen=True)
class FitInfo:
    """Diagnostics of :func:`fit_latent`.

    Attributes:
        loss: (steps,) per-step objective (on that step's point subset).
        seconds: [s] wall time of the optimisation.
        gamma: [-] γ = N(E_t)/N(X_prior) (inf when no ToA points were given).
        n_grid: [-] observed grid points N(E_t).
        n_toa: [-] known ToA points N(X_prior).
    """

    loss: NDArray[np.float64]
    seconds: float
    gamma: float
    n_grid: int
    n_toa: int


def _as(arr: ArrayLike | None, shape: tuple[int, ...], name: str) -> NDArray[np.float32]:
    """Copy to float32, check shape (-1 = any) and finiteness."""
    if arr is None:
        raise PlanningError(f"{name} is required for this model")
    a = np.array(arr, dtype=np.float32, copy=True)
    if a.ndim != len(shape) or any(s not in (-1, d) for s, d in zip(shape, a.shape, strict=True)):
        want = "(" + ", ".join("N" if s == -1 else str(s) for s in shape) + ")"
        raise PlanningError(f"{name} must have shape {want}, got {a.shape}")
    if not np.isfinite(a).all():
        raise PlanningError(f"{name} contains NaN or infinite values")
    return a


def fit_latent(
    model: AutoDecoder,
    grid_points: ArrayLike,
    cond: ArrayLike,
    *,
    d_t_obs: ArrayLike | None,
    d_o_obs: ArrayLike | None,
    toa_points: ArrayLike,
    toa_values: ArrayLike,
    z_init: ArrayLike,
    config: LatentFitConfig | None = None,
) -> tuple[NDArray[np.float32], FitInfo]:
    """Optimise the latent z with the network frozen (Eq. 9).

    Args:
        model: trained decoder; its weights and train/eval mode are left unchanged.
        grid_points: (N, 3) [-] observed grid points in [-1, 1].
        cond: (4,) condition c.
        d_t_obs: (N,) [1/m] D_t on the grid (required when the model predicts "t").
        d_o_obs: (N,) [1/m] D_o on the grid (required when the model predicts "o"; ignored otherwise).
        toa_points: (M, 3) [-] points with known D_toa (M may be 0).
        toa_values: (M,) [1/s] D_toa there (0 inside obstacles, 1/max(φ, ε) on τ_prior's tail).
        z_init: (latent_dim,) warm start, e.g. :meth:`LatentBank.warm_start`.
        config: optimisation settings.

    Returns:
        (z (latent_dim,), info).
    """
    cfg = config or LatentFitConfig()
    mc = model.config
    pts = _as(grid_points, (-1, 3), "grid_points")
    n = pts.shape[0]
    if n == 0:
        raise PlanningError("grid_points is empty")
    c = _as(cond, (COND_DIM,), "cond")
    z0 = _as(z_init, (mc.latent_dim,), "z_init")
    obs: dict[str, NDArray[np.float32]] = {}
    for ch, arr in (("t", d_t_obs), ("o", d_o_obs)):
        if ch in mc.channels:
            obs[ch] = _as(arr, (n,), f"d_{ch}_obs") / mc.target_scale
    tp = _as(toa_points, (-1, 3), "toa_points")
    m = tp.shape[0]
    tv = _as(toa_values, (m,), "toa_values") / mc.target_scale
    if m > 0 and "toa" not in mc.channels:
        raise PlanningError(f"toa_points given but the model predicts only {list(mc.channels)}")
    gamma = n / m if m > 0 else float("inf")
    w_toa_eff = cfg.loss_weights[2] * (gamma * m / n if m > 0 else 0.0)

    rng = np.random.default_rng(cfg.seed)
    z = torch.nn.Parameter(torch.from_numpy(z0))
    opt = torch.optim.Adam([z], lr=cfg.lr)
    cols = {ch: mc.channels.index(ch) for ch in mc.channels}
    grid_t = torch.from_numpy(pts)
    tp_t = torch.from_numpy(tp)
    tv_t = torch.from_numpy(tv)
    obs_t = {ch: torch.from_numpy(v) for ch, v in obs.items()}
    c_t = torch.from_numpy(c)[None]
    full = cfg.points_per_step == 0 or cfg.points_per_step >= n
    losses = np.zeros(cfg.steps)

    was_training = model.training
    req = [p.requires_grad for p in model.parameters()]
    old_threads = torch.get_num_threads()
    if cfg.threads > 0:
        torch.set_num_threads(cfg.threads)
    model.eval()
    for p in model.parameters():
        p.requires_grad_(False)
    t0 = time.perf_counter()
    try:
        for step in range(cfg.steps):
            idx = None if full else torch.from_numpy(rng.integers(0, n, size=cfg.points_per_step))
            x = grid_t if idx is None else grid_t[idx]
            pred = model(z[None], c_t, torch.cat([x, tp_t])[None])[0]
            pg, pt = pred[: x.shape[0]], pred[x.shape[0] :]
            loss = cfg.latent_reg * (z * z).sum()
            for ch, target in obs_t.items():
                y = target if idx is None else target[idx]
                loss = loss + cfg.loss_weights[("t", "o").index(ch)] * (pg[:, cols[ch]] - y).abs().mean()
            if m > 0:
                loss = loss + w_toa_eff * ((pt[:, cols["toa"]] - tv_t) ** 2).mean()
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            losses[step] = loss.item()
    finally:
        for p, r in zip(model.parameters(), req, strict=True):
            p.requires_grad_(r)
        model.train(was_training)
        torch.set_num_threads(old_threads)
    seconds = time.perf_counter() - t0
    _LOG.info(
        "latent fit: %d steps on %d grid + %d ToA points in %.3f s, loss %.4g -> %.4g",
        cfg.steps,
        n,
        m,
        seconds,
        losses[0],
        losses[-1],
    )
    info = FitInfo(loss=losses, seconds=seconds, gamma=gamma, n_grid=n, n_toa=m)
    return z.detach().numpy().copy(), info


def predict_fields(
    model: AutoDecoder, z: ArrayLike, cond: ArrayLike, grid_points: ArrayLike, chunk: int = 65536
) -> dict[str, NDArray[np.float32]]:
    """Decode the fields at ``grid_points``: {"t": (N,), "o": (N,), "toa": (N,)} in physical units.

    Args:
        z: (latent_dim,) latent code; cond: (4,) condition; grid_points: (N, 3) [-] in [-1, 1].
        chunk: [points] points per forward pass (bounds memory).
    """
    mc = model.config
    zz = torch.from_numpy(_as(z, (mc.latent_dim,), "z"))[None]
    cc = torch.from_numpy(_as(cond, (COND_DIM,), "cond"))[None]
    pts = torch.from_numpy(_as(grid_points, (-1, 3), "grid_points"))
    if chunk < 1:
        raise ConfigError(f"chunk={chunk} must be ≥ 1")
    was_training = model.training
    model.eval()
    try:
        with torch.inference_mode():
            parts = [model(zz, cc, pts[i : i + chunk][None])[0] for i in range(0, pts.shape[0], chunk)]
            out = torch.cat(parts) if parts else torch.zeros(0, len(mc.channels))
    finally:
        model.train(was_training)
    vals = (out * mc.target_scale).numpy()
    return {ch: np.ascontiguousarray(vals[:, j], dtype=np.float32) for j, ch in enumerate(mc.channels)}


def warm_start(latents: ArrayLike, scene_index: int) -> NDArray[np.float32]:
    """A copy of training scene ``scene_index``'s latent: (latent_dim,)."""
    lat: NDArray[np.float32] = np.asarray(latents, dtype=np.float32)
    if lat.ndim != 2 or not 0 <= scene_index < lat.shape[0]:
        raise PlanningError(f"scene_index {scene_index} outside 0..{lat.shape[0] - 1} of latents {lat.shape}")
    out: NDArray[np.float32] = np.array(lat[scene_index], dtype=np.float32, copy=True)
    return out


class LatentBank:
    """Nearest training sample by a caller-defined feature (local distance field + c), KD-tree backed.

    Args:
        features: (K, F) one feature per training sample (same scaling as the queries).
        scene_id: (K,) latent index of each sample.
        latents: (S, latent_dim) the trained latents.
    """

    def __init__(self, features: ArrayLike, scene_id: ArrayLike, latents: ArrayLike) -> None:
        f = _as(features, (-1, -1), "features").astype(np.float64)
        sid = np.array(scene_id, dtype=np.int64, copy=True).reshape(-1)
        lat = _as(latents, (-1, -1), "latents")
        if f.shape[0] == 0 or sid.shape[0] != f.shape[0]:
            raise PlanningError(f"need K ≥ 1 features and K scene ids, got {f.shape[0]} and {sid.shape[0]}")
        if sid.min() < 0 or sid.max() >= lat.shape[0]:
            raise PlanningError(f"scene_id values must be in 0..{lat.shape[0] - 1}")
        self.features = f
        self.scene_id = sid
        self.latents = lat
        self._tree = cKDTree(f)

    def nearest(self, feature: ArrayLike) -> tuple[int, float]:
        """(index of the nearest training sample, its feature distance) for ``feature`` (F,)."""
        q = _as(feature, (self.features.shape[1],), "feature").astype(np.float64)
        dist, idx = self._tree.query(q, k=1)
        return int(idx), float(dist)

    def warm_start(self, feature: ArrayLike) -> tuple[NDArray[np.float32], int, float]:
        """(latent (latent_dim,) of the nearest sample's scene, sample index, feature distance)."""
        idx, dist = self.nearest(feature)
        return warm_start(self.latents, int(self.scene_id[idx])), idx, dist


def prior_toa_anchors(
    positions: ArrayLike, times: ArrayLike, tail_length: float = 0.05, eps: float = 0.025
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Known D_toa on the last ``tail_length`` of a prior trajectory that ends at the goal.

    Args:
        positions: (T, 3) [m] prior wrist path ending at the contact pose.
        times: (T,) [s] increasing sample times.
        tail_length: [m] arc length kept before the end (paper: 5 cm).
        eps: [s] ε of D_toa = 1 / max(φ, ε), φ = remaining time to the goal.

    Returns:
        (positions (M, 3) [m], D_toa (M,) [1/s]) — convert positions with ``to_unit_cube``.
    """
    p = np.asarray(positions, dtype=np.float64)
    t = np.asarray(times, dtype=np.float64).reshape(-1)
    if p.ndim != 2 or p.shape[1] != 3 or t.shape != (p.shape[0],) or p.shape[0] < 2:
        raise PlanningError(f"positions must be (T, 3) and times (T,) with T ≥ 2, got {p.shape}, {t.shape}")
    if not (np.isfinite(p).all() and np.isfinite(t).all()) or np.any(np.diff(t) <= 0.0):
        raise PlanningError("prior positions/times must be finite and times strictly increasing")
    if not (tail_length > 0.0 and eps > 0.0):
        raise ConfigError(f"tail_length and eps must be > 0, got {tail_length}, {eps}")
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    from_end = np.concatenate([np.cumsum(seg[::-1])[::-1], [0.0]])
    keep = from_end <= tail_length
    phi = t[-1] - t[keep]
    return p[keep].copy(), 1.0 / np.maximum(phi, eps)
