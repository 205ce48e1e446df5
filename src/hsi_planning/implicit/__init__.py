"""The neural implicit trajectory planner's auto-decoder (CHOICE §4): network, training, latent fit.

- :mod:`.model`: :class:`AutoDecoder` (z, c, x) → (D_t, D_o, D_toa) and its config.
- :mod:`.dataset`: :class:`FieldDataset`, the in-memory training set, and batch sampling.
- :mod:`.train`: :func:`train` (Eq. 8) and checkpoint I/O.
- :mod:`.latent`: :func:`fit_latent` (Eq. 9), :class:`LatentBank` warm start, :func:`predict_fields`.
"""

from hsi_planning.implicit.dataset import Batch, FieldDataset
from hsi_planning.implicit.latent import (
    FitInfo,
    LatentBank,
    LatentFitConfig,
    fit_latent,
    predict_fields,
    prior_toa_anchors,
    warm_start,
)
from hsi_planning.implicit.model import CHANNELS, COND_DIM, AutoDecoder, AutoDecoderConfig, to_unit_cube
from hsi_planning.implicit.train import (
    Checkpoint,
    TrainConfig,
    TrainResult,
    field_loss,
    load_checkpoint,
    save_checkpoint,
    train,
)

__all__ = [
    "CHANNELS",
    "COND_DIM",
    "AutoDecoder",
    "AutoDecoderConfig",
    "Batch",
    "Checkpoint",
    "FieldDataset",
    "FitInfo",
    "LatentBank",
    "LatentFitConfig",
    "TrainConfig",
    "TrainResult",
    "field_loss",
    "fit_latent",
    "load_checkpoint",
    "predict_fields",
    "prior_toa_anchors",
    "save_checkpoint",
    "to_unit_cube",
    "train",
    "warm_start",
]
