"""Auto-decoder of the implicit planner: network wiring, training, checkpoints, runtime latent fit."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import torch

from hsi_planning.config import from_mapping
from hsi_planning.errors import ConfigError, PlanningError
from hsi_planning.implicit import (
    AutoDecoder,
    AutoDecoderConfig,
    FieldDataset,
    LatentBank,
    LatentFitConfig,
    TrainConfig,
    TrainResult,
    fit_latent,
    load_checkpoint,
    predict_fields,
    prior_toa_anchors,
    save_checkpoint,
    to_unit_cube,
    train,
)

HALF = 0.4  # [m] half edge of the object-centric grid
EPS = 0.025  # [m] / [s]
N_GRID = 12
TINY = AutoDecoderConfig(latent_dim=16, n_layers=4, width=64, skip_layer=2)
# Target centres (grid-local, [-1, 1]) of the synthetic training scenes, and one held out.
CENTRES = np.array([[-0.5, -0.5, 0.0], [0.5, -0.5, 0.0], [-0.5, 0.5, 0.0], [0.5, 0.5, 0.0]])
HELD_OUT = np.array([0.3, 0.4, 0.0])


def _grid(n: int = N_GRID) -> np.ndarray:
    ax = np.linspace(-1.0, 1.0, n)
    return np.stack(np.meshgrid(ax, ax, ax, indexing="ij"), axis=-1).reshape(-1, 3)


def _fields(centre: np.ndarray, pts: np.ndarray) -> dict[str, np.ndarray]:
    """Analytic stand-ins: D_t inverse distance to a 6 cm sphere at ``centre``, D_o to a fixed one,
    D_toa inverse time of a 0.5 m/s straight approach to the sphere."""
    d_t = np.maximum(np.linalg.norm((pts - centre) * HALF, axis=1) - 0.06, 0.0)
    d_o = np.maximum(np.linalg.norm((pts - [0.0, 0.0, 0.6]) * HALF, axis=1) - 0.1, 0.0)
    return {
        "t": 1.0 / np.maximum(d_t, EPS),
        "o": 1.0 / np.maximum(d_o, EPS),
        "toa": 1.0 / np.maximum(d_t / 0.5, EPS),
    }


def _dataset() -> FieldDataset:
    pts = _grid()
    grids = [_fields(c, pts) for c in CENTRES]
    cond = [[0.8, 1.0, 0.0, 0.0]] * len(CENTRES)
    return FieldDataset.from_grids(pts, grids, scene_id=np.arange(len(CENTRES)), cond=cond)


def _err(pred: dict[str, np.ndarray], true: dict[str, np.ndarray]) -> float:
    """Mean absolute error over the channels [1/m]."""
    return float(np.mean([np.abs(pred[c] - true[c]).mean() for c in pred]))


TINY_TRAIN = TrainConfig(
    model=TINY,
    steps=400,
    batch_size=4,
    points_per_sample=512,
    lr_net=2e-3,
    lr_latent=1e-2,
    lr_decay_every=250,
    threads=1,
)


@pytest.fixture(scope="module")
def trained() -> TrainResult:
    return train(_dataset(), TINY_TRAIN, progress=False)


def test_forward_shapes_and_non_negative() -> None:
    torch.manual_seed(0)
    for cfg in (TINY, dataclasses.replace(TINY, channels=("t", "toa"), pe_frequencies=4, norm="layer")):
        model = AutoDecoder(cfg)
        z = torch.randn(3, cfg.latent_dim) * 10.0
        c = torch.randn(3, 4) * 10.0
        x = torch.rand(3, 50, 3) * 20.0 - 10.0
        out = model(z, c, x)
        assert out.shape == (3, 50, len(cfg.channels))
        assert bool((out >= 0.0).all())
    assert AutoDecoder().n_parameters() > 300_000  # paper size 6×256


def test_skip_layer_reinjects_input() -> None:
    torch.manual_seed(0)
    cfg = dataclasses.replace(TINY, norm="none")
    model = AutoDecoder(cfg)
    assert model.layers[cfg.skip_layer].in_features == cfg.width + cfg.input_dim
    assert model.layers[1].in_features == cfg.width
    # Cut the path through the layer before the skip: the output must still depend on x (via the skip).
    with torch.no_grad():
        model.layers[cfg.skip_layer - 1].weight.zero_()
    z, c = torch.zeros(1, cfg.latent_dim), torch.zeros(1, 4)
    x = torch.rand(1, 20, 3) * 2 - 1
    with torch.no_grad():
        out = model(z, c, x)
        assert float(out.std(dim=1).max()) > 1e-4  # varies over the points
    no_skip = AutoDecoder(dataclasses.replace(cfg, skip_layer=-1))
    with torch.no_grad():
        no_skip.layers[cfg.skip_layer - 1].weight.zero_()
        assert float(no_skip(z, c, x).std(dim=1).max()) < 1e-7


def test_training_fits_and_latents_are_scene_specific(trained: TrainResult) -> None:
    loss = trained.history["loss"]
    assert loss.shape == (TINY_TRAIN.steps,)
    assert loss[-20:].mean() < loss[:5].mean() / 20.0  # measured ≈ 60×
    assert trained.latents.shape == (len(CENTRES), TINY.latent_dim)
    pts = _grid()
    cond = np.array([0.8, 1.0, 0.0, 0.0])
    errors = np.array(
        [
            [_err(predict_fields(trained.model, z, cond, pts), _fields(c, pts)) for c in CENTRES]
            for z in trained.latents
        ]
    )
    assert np.array_equal(errors.argmin(axis=1), np.arange(len(CENTRES)))
    assert np.all(np.diag(errors) < 0.6 * np.sort(errors, axis=1)[:, 1])


def test_training_is_deterministic() -> None:
    cfg = dataclasses.replace(TINY_TRAIN, steps=15)
    a = train(_dataset(), cfg, progress=False)
    b = train(_dataset(), cfg, progress=False)
    assert np.array_equal(a.history["loss"], b.history["loss"])
    assert np.array_equal(a.latents, b.latents)
    c = train(_dataset(), dataclasses.replace(cfg, seed=1), progress=False)
    assert not np.array_equal(a.history["loss"], c.history["loss"])


def test_checkpoint_round_trip(trained: TrainResult, tmp_path: Path) -> None:
    path = tmp_path / "ad.pt"
    save_checkpoint(path, trained.model, trained.latents, trained.config, {"scenes": 4, "note": "synthetic"})
    ck = load_checkpoint(path)
    assert ck.config == trained.config
    assert ck.meta == {"scenes": 4, "note": "synthetic"}
    assert np.array_equal(ck.latents, trained.latents)
    pts, cond = _grid(6), np.array([0.8, 1.0, 0.0, 0.0])
    a = predict_fields(trained.model, trained.latents[1], cond, pts)
    b = predict_fields(ck.model, ck.latents[1], cond, pts)
    for ch in a:
        assert np.array_equal(a[ch], b[ch])
    # Default (paper) network with 300 latents stays well within the 10 MB budget.
    big = tmp_path / "paper.pt"
    size = save_checkpoint(big, AutoDecoder(), np.zeros((300, 128), np.float32), TrainConfig())
    assert size == big.stat().st_size < 10 * 1024 * 1024
    assert load_checkpoint(big).model.n_parameters() == AutoDecoder().n_parameters()
    with pytest.raises(PlanningError, match="not allowed"):
        save_checkpoint(tmp_path / "x.pt", trained.model, trained.latents, trained.config, {"a": np.ones(2)})
    (tmp_path / "junk.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(PlanningError, match="checkpoint"):
        load_checkpoint(tmp_path / "junk.pt")


def test_fit_latent_improves_on_warm_start(trained: TrainResult) -> None:
    pts = _grid()
    cond = np.array([0.8, 1.0, 0.0, 0.0])
    truth = _fields(HELD_OUT, pts)
    # Warm start: nearest training scene by a caller feature (here: the target centre + c).
    bank = LatentBank(np.hstack([CENTRES, np.tile(cond, (4, 1))]), np.arange(4), trained.latents)
    z0, idx, dist = bank.warm_start(np.concatenate([HELD_OUT, cond]))
    assert idx == 3 and dist == pytest.approx(np.linalg.norm(HELD_OUT - CENTRES[3]))
    # Known ToA: the last 5 cm of a straight prior ending on the sphere, with its remaining time.
    goal = HELD_OUT * HALF + np.array([0.0, -0.06, 0.0])
    path = goal + np.linspace(0.3, 0.0, 31)[:, None] * np.array([0.0, -1.0, 0.0])
    anchors, toa = prior_toa_anchors(path, np.linspace(0.0, 0.6, 31), tail_length=0.05, eps=EPS)
    assert anchors.shape[0] == 6 and toa[-1] == pytest.approx(1.0 / EPS)
    cfg = LatentFitConfig(steps=100, lr=1e-2, points_per_step=512)
    z, info = fit_latent(
        trained.model,
        pts,
        cond,
        d_t_obs=truth["t"],
        d_o_obs=truth["o"],
        toa_points=to_unit_cube(anchors, [0, 0, 0], HALF),
        toa_values=toa,
        z_init=z0,
        config=cfg,
    )
    assert info.gamma == pytest.approx(pts.shape[0] / 6) and info.loss.shape == (100,)
    before = _err(predict_fields(trained.model, z0, cond, pts), truth)
    after = _err(predict_fields(trained.model, z, cond, pts), truth)
    assert after < 0.8 * before
    assert np.array_equal(z0, bank.warm_start(np.concatenate([HELD_OUT, cond]))[0])  # z0 not aliased
    assert all(p.requires_grad for p in trained.model.parameters())  # network left as it was


def test_dataset_sampling_and_importance() -> None:
    ds = _dataset()
    rng = np.random.default_rng(0)
    b = ds.sample_batch(rng, batch_size=3, n_points=200, near_share=0.5)
    assert b.points.shape == (3, 200, 3) and b.targets.shape == (3, 200, 3)
    assert np.array_equal(b.scene, ds.scene_id[b.sample])
    toa = b.targets[:, :, 2]
    assert toa[:, 100:].mean() > 2.0 * toa[:, :100].mean()  # the near half comes from high D_toa
    ablation = ds.select_channels(("t", "toa"))
    assert ablation.targets.shape[2] == 2
    with pytest.raises(ConfigError, match="toa"):
        ds.select_channels(("t", "o")).sample_batch(rng, 2, 10, near_share=0.5)


def test_bad_inputs_raise() -> None:
    pts = _grid(4)
    good = np.ones((2, pts.shape[0], 3), np.float32)
    cond = np.zeros((2, 4))
    with pytest.raises(PlanningError, match="NaN"):
        FieldDataset(pts, np.where(np.arange(3) == 1, np.nan, good), [0, 1], cond)
    with pytest.raises(PlanningError, match=r"targets must be \(K, N, C\)"):
        FieldDataset(pts, good[:, :-1], [0, 1], cond)
    with pytest.raises(PlanningError, match="cond must be"):
        FieldDataset(pts, good, [0, 1], np.zeros((2, 3)))
    with pytest.raises(PlanningError, match="every index"):
        FieldDataset(pts, good, [0, 2], cond)
    with pytest.raises(ConfigError, match="skip_layer"):
        AutoDecoderConfig(n_layers=4, skip_layer=4)
    with pytest.raises(ConfigError, match="channels"):
        AutoDecoderConfig(channels=("toa", "t"))
    with pytest.raises(ConfigError, match="unknown"):
        from_mapping(TrainConfig, {"model": {"widht": 3}})
    with pytest.raises(ConfigError, match="model channels"):
        train(
            FieldDataset(pts, good[:, :, :2], [0, 1], cond, channels=("t", "o")), TINY_TRAIN, progress=False
        )
    model = AutoDecoder(TINY)
    with pytest.raises(PlanningError, match=r"c must be \(B, 4\)"):
        model(torch.zeros(1, 16), torch.zeros(1, 3), torch.zeros(1, 5, 3))
    n = pts.shape[0]
    kw = {"d_t_obs": np.ones(n), "d_o_obs": np.ones(n), "toa_points": np.zeros((0, 3)), "toa_values": []}
    with pytest.raises(PlanningError, match=r"cond must have shape \(4\)"):
        fit_latent(model, pts, np.zeros(5), z_init=np.zeros(16), **kw)  # type: ignore[arg-type]
    with pytest.raises(PlanningError, match="d_t_obs must have shape"):
        fit_latent(model, pts, np.zeros(4), z_init=np.zeros(16), **{**kw, "d_t_obs": np.ones(n - 1)})  # type: ignore[arg-type]
    with pytest.raises(PlanningError, match="d_o_obs contains NaN"):
        fit_latent(model, pts, np.zeros(4), z_init=np.zeros(16), **{**kw, "d_o_obs": np.full(n, np.nan)})  # type: ignore[arg-type]
    with pytest.raises(PlanningError, match="z_init"):
        fit_latent(model, pts, np.zeros(4), z_init=np.zeros(128), **kw)  # type: ignore[arg-type]
