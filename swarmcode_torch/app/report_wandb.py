"""Weights & Biases, optional: the same scalars as TensorBoard, the config, the replays
(`WandbReporter`, `evolve --wandb`)."""

from __future__ import annotations

import math
import os
import re
import warnings
from pathlib import Path

from ..coevo.evolve import Evolution, GenerationResult
from .records import HISTOGRAMS, SCALAR_TAGS, scalars
from .report_tensorboard import best_scalars, replay_strip
from .reporter import Reporter
from .run_record import app_record

#: What to install for `WandbReporter` (`evolve --wandb`).
WANDB_INSTALL = 'pip install -e ".[wandb]" in the source tree'


def require_wandb():
    """The `wandb` module; ImportError with a one-line message naming the extra to install."""
    try:
        import wandb
    except ImportError:
        raise ImportError(
            f"Weights & Biases logging needs the wandb package: {WANDB_INSTALL}"
        ) from None
    return wandb


WANDB_MODES = ("online", "offline", "disabled")
_WANDB_PROJECT = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,127}$")


def check_wandb_settings(project, mode=None) -> None:
    """ValueError, one line, for a W&B project name W&B refuses (empty, with '/', not a
    string) or a mode (or WANDB_MODE) that is not online, offline or disabled: said before a
    run directory is made rather than as wandb's traceback later."""
    if not isinstance(project, str) or not _WANDB_PROJECT.match(project):
        raise ValueError(
            f"wandb project must be 1-128 letters, digits, '_', '.' or '-' (no '/'), "
            f"got {project!r:.60}"
        )
    env = os.environ.get("WANDB_MODE")
    for what, v in (("mode", mode), ("WANDB_MODE", env)):
        if v is not None and v not in WANDB_MODES and not (what == "WANDB_MODE" and v == ""):
            raise ValueError(f"{what} must be one of {', '.join(WANDB_MODES)}, got {v!r:.60}")


def _first_line(e: BaseException) -> str:
    """'ErrorType: its first non-blank line' (at most 200 characters of it)."""
    lines = [ln.strip() for ln in str(e).splitlines() if ln.strip()]
    return f"{type(e).__name__}: {lines[0][:200]}" if lines else type(e).__name__


def _wandb_run_id(run_dir: Path) -> str:
    """A W&B run id of a run directory: the same on every resume of it, so that its parts
    continue one W&B run."""
    import hashlib

    return hashlib.sha256(str(Path(run_dir).resolve()).encode()).hexdigest()[:16]


class WandbReporter(Reporter):
    """Logs a run to Weights & Biases: the config (every key of config.toml), every
    generation's scalars under the TensorBoard tags (`records.SCALAR_TAGS` and the best team's,
    `HPARAM_METRICS`) and gene histograms, a replay of the generation's best team every
    `render_every` generations and one of the run's best team (`best/replay`) at its end (0:
    never); at its end, the run directory's checkpoint and replays as an artifact
    (`wandb_runs.log_run_files`). Steps are generations. The W&B run is named after the run
    directory, and its id is derived from it, so a resumed run continues its W&B run; `project`,
    `entity`, `mode` ("online", "offline", or None: wandb's default and WANDB_MODE) and any
    other `wandb.init` keyword (`init`) as wandb takes them. Needs the `wandb` package (`WANDB_INSTALL`), imported
    when the reporter is made."""

    def __init__(
        self,
        project: str = "swarmcode-torch",
        run_dir: Path | None = None,
        render_every: int = 50,
        entity: str | None = None,
        mode: str | None = None,
        **init,
    ):
        self.wandb = require_wandb()
        check_wandb_settings(project, mode)
        self.project, self.entity, self.mode = project, entity, mode
        self.run_dir = Path(run_dir) if run_dir is not None else None
        self.render_every = render_every
        self.init = init
        self.run = None

    def on_start(self, ev: Evolution) -> None:
        from .records import json_clean

        init = {
            "project": self.project,
            "entity": self.entity,
            "mode": self.mode,
            "config": json_clean(ev.cfg.to_dict()),
        }
        if self.run_dir is not None:
            # W&B's own files go inside the run directory, never into the working directory
            init.update(
                name=self.run_dir.name,
                id=_wandb_run_id(self.run_dir),
                resume="allow",
                dir=str(self.run_dir),
            )
        try:
            self.run = self.wandb.init(
                **{k: v for k, v in {**init, **self.init}.items() if v is not None}
            )
        except Exception as e:  # noqa: BLE001 - no network, a bad key: the run goes on
            self._drop(e)

    def _drop(self, e: BaseException) -> None:
        """Go on without W&B, saying why in one line (the run's own files are unaffected)."""
        self.run = None
        warnings.warn(
            f"Weights & Biases logging stopped ({_first_line(e)}); the run goes on without it",
            RuntimeWarning,
            stacklevel=2,
        )

    def on_generation(self, ev: Evolution, result: GenerationResult) -> None:
        if self.run is None:
            return
        try:
            self._log_generation(ev, result)
        except Exception as e:  # noqa: BLE001
            self._drop(e)

    def _log_generation(self, ev: Evolution, result: GenerationResult) -> None:
        row = scalars(result)
        log = {tag: float(row[tag]) if row[tag] is not None else math.nan for tag in SCALAR_TAGS}
        log.update(best_scalars(result))
        for tag, name in HISTOGRAMS.items():
            log[tag] = self.wandb.Histogram(getattr(result, name).float().numpy())
        if self.render_every and result.generation % self.render_every == 0:
            log["team/replay"] = self.wandb.Image(
                replay_strip(ev, result.team["designs"], seed=result.generation),
                caption=f"generation {result.generation}: the generation's best team",
            )
        self.run.log(log, step=result.generation)

    def on_end(self, ev: Evolution) -> None:
        if self.run is None:
            return
        best = app_record(ev).best
        if self.render_every and ev.state.history and best and best.get("designs"):
            step = ev.state.history[-1]["generation"]
            self.run.log(
                {
                    "best/replay": self.wandb.Image(
                        replay_strip(ev, best["designs"], seed=step),
                        caption=f"the run's best team (generation {best.get('generation')})",
                    )
                },
                step=step,
            )
        error = None
        if self.run_dir is not None:  # the checkpoint is written: the reporters before this
            from .wandb_runs import log_run_files

            try:
                log_run_files(self.wandb, self.run, self.run_dir)
            except Exception as e:  # noqa: BLE001 - the run's own files are written
                error = e
        self.close()
        if error is not None:
            self._drop(error)

    def close(self) -> None:
        """Finish the W&B run (its files written; synced when online)."""
        if self.run is not None:
            self.run.finish()
            self.run = None
