"""Reporting: TensorBoard (scalars, histograms, the species-composition figure, replays, the
Custom Scalars layout, the config and its hyperparameters), metrics.csv (every scalar, one row
per generation) and, optional, Weights & Biases (the same scalars, the config, the replays).

One module a sink: `report_tensorboard`, `report_csv`, `report_wandb`; every public name is
importable from here. `records` makes the scalars all three write."""

from __future__ import annotations

from .files import METRICS_FILE
from .records import HISTOGRAMS, SCALAR_TAGS, scalars
from .report_csv import CsvReporter, read_metrics_csv
from .report_tensorboard import (
    CUSTOM_SCALARS,
    HPARAM_FIRST,
    HPARAM_KEYS,
    HPARAM_METRICS,
    RUN_SIZE_KEYS,
    TensorBoardReporter,
    best_scalars,
    composition_figure,
    config_markdown,
    custom_scalars_layout,
    figure_image,
    hparams,
    hparams_summaries,
    replay_strip,
)
from .report_wandb import (
    WANDB_INSTALL,
    WANDB_MODES,
    WandbReporter,
    check_wandb_settings,
    require_wandb,
)

__all__ = [
    "METRICS_FILE",
    "CUSTOM_SCALARS",
    "CsvReporter",
    "HISTOGRAMS",
    "HPARAM_FIRST",
    "HPARAM_KEYS",
    "HPARAM_METRICS",
    "RUN_SIZE_KEYS",
    "SCALAR_TAGS",
    "TensorBoardReporter",
    "WANDB_INSTALL",
    "WANDB_MODES",
    "WandbReporter",
    "best_scalars",
    "check_wandb_settings",
    "composition_figure",
    "config_markdown",
    "custom_scalars_layout",
    "figure_image",
    "hparams",
    "hparams_summaries",
    "read_metrics_csv",
    "replay_strip",
    "require_wandb",
    "scalars",
]
