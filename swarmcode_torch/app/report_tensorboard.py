"""TensorBoard: scalars, histograms, the species-composition figure, replays, the Custom Scalars
layout, the config and its hyperparameters (`TensorBoardReporter`; docs/TENSORBOARD.md).

Matplotlib and TensorBoard are imported inside the functions that need them; figures are drawn
on `matplotlib.figure.Figure` with the Agg canvas, never through pyplot or a backend switch."""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import TYPE_CHECKING

from ..coevo.evolve import Evolution, GenerationResult
from .records import HISTOGRAMS, SCALAR_TAGS, scalars
from .reporter import Reporter
from .run_record import app_record

if TYPE_CHECKING:
    from matplotlib.figure import Figure


def _check_history(history) -> None:
    """ValueError, one line, unless `history` is a list of composition records: dicts with an
    integer `generation` and `population` and `team` tables of species id -> count."""
    if not isinstance(history, (list, tuple)):
        raise ValueError(
            f"history must be a list of composition records, got {type(history).__name__}"
        )
    for i, h in enumerate(history):
        ok = (
            isinstance(h, dict)
            and isinstance(h.get("generation"), int)
            and not isinstance(h.get("generation"), bool)
            and all(
                isinstance(h.get(k), dict)
                and all(
                    str(s).lstrip("-").isdigit() and isinstance(n, int) and not isinstance(n, bool)
                    for s, n in h[k].items()
                )
                for k in ("population", "team")
            )
        )
        if not ok:
            raise ValueError(
                f"history[{i}] is not a composition record ({{'generation': int, 'population': "
                f"{{species: count}}, 'team': {{species: robots}}}}), got {str(h)[:60]!r}"
            )


def composition_figure(history: list[dict], legend: int = 8) -> Figure:
    """Species composition of the population and of the best team per generation (paper Fig. 5).

    Stacked areas, one colour per species id. Drawn object-oriented (`matplotlib.figure.Figure`):
    no pyplot, no backend change, so a notebook keeps its inline plots; the figure displays as the
    value of a cell (`IPython.display.display(fig)`) and `fig.savefig(path)` writes it.

    Args:
        history: the run's species history (`RunResult.species`).
        legend: each panel's legend names its `legend` largest species (most individuals, or
            robots, over the generations shown) by the ids `swarmcode-torch inspect` prints,
            largest first (0: no legend).

    Returns:
        A matplotlib `Figure`.
    """
    _check_history(history)
    from matplotlib import colormaps
    from matplotlib.figure import Figure

    gens = [h["generation"] for h in history]
    fig = Figure(figsize=(12, 3.6))
    axes = fig.subplots(1, 2, sharex=True)
    for ax, key, title in ((axes[0], "population", "population"), (axes[1], "team", "best team")):
        ids = sorted({int(s) for h in history for s in h[key]})
        rows = [[h[key].get(s, h[key].get(str(s), 0)) for h in history] for s in ids]
        if ids:
            cmap = colormaps["tab20"]
            bands = ax.stackplot(gens, rows, colors=[cmap(i % 20) for i in ids], linewidth=0)
            largest = sorted(range(len(ids)), key=lambda j: (-sum(rows[j]), ids[j]))[:legend]
            if largest:
                more = len(ids) - len(largest)
                ax.legend(
                    [bands[j] for j in largest],
                    [str(ids[j]) for j in largest],
                    title="species" + (f"\n(+{more} more)" if more else ""),
                    loc="upper left",
                    bbox_to_anchor=(1.0, 1.0),
                    fontsize=8,
                    title_fontsize=8,
                    frameon=False,
                    handlelength=1.2,
                )
        ax.set_title(f"species in the {title}")
        ax.set_xlabel("generation")
        ax.set_ylabel("individuals" if key == "population" else "robots")
    fig.tight_layout()
    return fig


def figure_image(fig):
    """[H, W, 3] uint8: a matplotlib Figure rendered by the Agg canvas (no pyplot)."""
    import numpy as np
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].copy()


#: Scalars of the best team of the run so far (`GenerationResult.best`), logged every
#: generation beside `records.SCALAR_TAGS`: tag -> key of `best_team.figures` (best/fitness:
#: its re-evaluated mean, with the bounds of its 95 % interval; best/single_trial_fitness: the
#: highest single evaluation of the run). They are also the metrics of TensorBoard's HParams
#: tab (the last value of each run), so that no scalar is written only for it.
HPARAM_METRICS = {
    "best/fitness": "fitness",
    "best/fitness_ci_lo": "fitness_ci_lo",
    "best/fitness_ci_hi": "fitness_ci_hi",
    "best/single_trial_fitness": "single_trial_fitness",
    "best/cost": "cost",
    "best/species": "species",
    "best/niches": "niches",
    "best/deliveries": "deliveries",
}

#: Config keys shown in TensorBoard's HParams tab for every run, beside the keys whose value
#: differs from the run's preset: the first `HPARAM_FIRST` and the algorithm settings that
#: differ from the preset are marked as those that differ, which the tab lists first and shows
#: (its first five columns); the run's size after them.
HPARAM_KEYS = (
    "preset",
    "scenario",
    "budget",
    "objective",
    "seed",
    "population",
    "swarm_size",
    "generations",
)
HPARAM_FIRST = ("preset", "scenario", "budget", "objective", "seed")
#: Settings of a run's size and of where it computes (listed after the others).
RUN_SIZE_KEYS = ("population", "swarm_size", "generations", "trials", "ticks", "device", "compile")

#: TensorBoard's Custom Scalars tab: category -> chart title -> the tags drawn together.
CUSTOM_SCALARS = {
    "species and niches": {
        "species: population, generation's team, best team": [
            "species/count",
            "team/species",
            "best/species",
        ],
        "niches: generation's team, best team": ["team/niches", "best/niches"],
        "species founded and extinct": ["species/founded", "species/extinct"],
        "median species age: population, team": ["species/median_age", "team/median_age"],
    },
    "fitness, cost and budget": {
        "fitness: population best and mean, generation's team, best team": [
            "fitness/best",
            "fitness/mean",
            "team/fitness",
            "best/fitness",
        ],
        "best team: re-evaluated fitness, its 95 % interval, the highest single evaluation": [
            "best/fitness",
            "best/fitness_ci_lo",
            "best/fitness_ci_hi",
            "best/single_trial_fitness",
        ],
        "generation's team: single evaluation, re-evaluated": [
            "team/fitness",
            "team/fitness_reeval",
        ],
        "team cost and budget ($)": ["team/cost", "team/budget", "best/cost"],
        "deliveries: generation's team, best team": [
            "team/deliveries",
            "team/deliveries_individual",
            "team/deliveries_collab",
            "best/deliveries",
        ],
    },
    "time": {
        "seconds per generation": [
            "perf/generation_seconds",
            "perf/eval_seconds",
            "perf/sim_seconds",
            "perf/reeval_seconds",
        ]
    },
}


def best_scalars(result: GenerationResult) -> dict[str, float]:
    """The run's best team so far as scalars (`HPARAM_METRICS`); NaN for a missing value."""
    from .best_team import figures

    found = figures(result.best)
    return {
        tag: found[key] if found.get(key) is not None else math.nan
        for tag, key in HPARAM_METRICS.items()
    }


def custom_scalars_layout() -> dict:
    """`CUSTOM_SCALARS` as `SummaryWriter.add_custom_scalars` takes it: each chart a multiline
    chart whose tags are anchored regular expressions (each names one tag exactly)."""

    return {
        cat: {
            title: ["Multiline", [f"^{re.escape(t)}$" for t in tags]]
            for title, tags in charts.items()
        }
        for cat, charts in CUSTOM_SCALARS.items()
    }


def _hparam_value(v):
    return v if isinstance(v, (str, bool)) else float(v)


def hparams(ev: Evolution) -> tuple[dict, dict]:
    """The run's hyperparameters for TensorBoard's HParams tab: `HPARAM_KEYS` (the robots per
    team as the run uses them) and every other config key whose value differs from the run's
    preset; unset ones are left out. Returns ({key: value}, {key: listed first}): first are
    `HPARAM_FIRST` and the algorithm settings that differ from the preset, not the run's size
    (`RUN_SIZE_KEYS`)."""
    from ..coevo.config import PRESETS, preset_config

    cfg = ev.cfg.to_dict()
    base = preset_config(ev.cfg.preset if ev.cfg.preset in PRESETS else "default").to_dict()
    differs = {k: cfg[k] != base.get(k) for k in cfg}
    keys = [k for k in HPARAM_KEYS if k in cfg] + [
        k for k in cfg if differs[k] and k not in HPARAM_KEYS
    ]
    hp = {}
    for k in keys:
        v = ev.ctx.eval_cfg.swarm_size if k == "swarm_size" and cfg[k] is None else cfg[k]
        if v is not None:
            hp[k] = _hparam_value(v)
    return hp, {k: k in HPARAM_FIRST or (differs[k] and k not in RUN_SIZE_KEYS) for k in hp}


def config_markdown(ev: Evolution) -> str:
    rows = "\n".join(f"|{k}|{v}|" for k, v in ev.cfg.to_dict().items())
    return f"|parameter|value|\n|-|-|\n{rows}"


def replay_strip(ev: Evolution, designs: list[dict], seed: int, frames: int = 3, dpi: int = 80):
    """[H, W, 3] uint8: frames of one episode of a team (start to end), side by side, each as
    a GIF frame is drawn (dpi 80: the legend's 8-point text is about 9 pixels high)."""
    import numpy as np

    from .frames import frame_image
    from .render import record_episode, team_genome

    genome, team = team_genome(designs, ev.cfg.tag_length)
    ticks = ev.ctx.eval_cfg.ticks
    ep = record_episode(
        genome, team, ev.ctx.scenario, seed, ticks=ticks, every=max(1, ticks // (frames - 1))
    )
    picks = np.linspace(0, len(ep.snapshots) - 1, frames).round().astype(int)
    return np.concatenate([frame_image(ep, int(i), dpi=dpi) for i in picks], axis=1)


def hparams_summaries(ev: Evolution) -> list:
    """The summaries of TensorBoard's HParams plugin for one run: the experiment (its
    hyperparameters, those that differ from the preset first, and `HPARAM_METRICS` as its
    metrics) and the session's start (the run's values)."""
    from tensorboard.compat.proto.summary_pb2 import Summary
    from tensorboard.plugins.hparams import api_pb2, metadata, plugin_data_pb2

    hp, differs = hparams(ev)
    kind = {
        str: api_pb2.DATA_TYPE_STRING,
        bool: api_pb2.DATA_TYPE_BOOL,
        float: api_pb2.DATA_TYPE_FLOAT64,
    }
    # a key of every run that this run leaves unset (no budget) is a column all the same: the
    # tab takes its columns from one run's experiment
    unset = {
        k: "" if k == "preset" else 0.0
        for k in HPARAM_KEYS
        if k not in hp and k in ev.cfg.to_dict()
    }
    infos = [
        api_pb2.HParamInfo(name=k, type=kind[type(v)], differs=differs.get(k, k in HPARAM_FIRST))
        for k, v in {**hp, **unset}.items()
    ]
    metrics = [
        api_pb2.MetricInfo(name=api_pb2.MetricName(tag=t), display_name=f"best {k}")
        for t, k in HPARAM_METRICS.items()
    ]
    start = plugin_data_pb2.SessionStartInfo()
    for k, v in hp.items():
        if isinstance(v, str):
            start.hparams[k].string_value = v
        elif isinstance(v, bool):
            start.hparams[k].bool_value = v
        else:
            start.hparams[k].number_value = v
    out = []
    for tag, data in (
        (
            metadata.EXPERIMENT_TAG,
            plugin_data_pb2.HParamsPluginData(
                experiment=api_pb2.Experiment(hparam_infos=infos, metric_infos=metrics)
            ),
        ),
        (
            metadata.SESSION_START_INFO_TAG,
            plugin_data_pb2.HParamsPluginData(session_start_info=start),
        ),
    ):
        out.append(
            Summary(value=[Summary.Value(tag=tag, metadata=metadata.create_summary_metadata(data))])
        )
    return out


class TensorBoardReporter(Reporter):
    """Writes every generation's scalars (`records.SCALAR_TAGS` and the run's best team so
    far, `HPARAM_METRICS`) and gene histograms; the composition figure every `figure_every`
    generations and at the end; a replay of the generation's best team every `render_every`
    generations and one of the run's best team (`best/replay`) at its last generation (0:
    never). At the start of a run (or of each resumed part) the config as text, the Custom
    Scalars layout (`CUSTOM_SCALARS`) and the hyperparameters (`hparams`) with the best team's
    scalars as their metrics, so that TensorBoard's HParams tab compares runs."""

    def __init__(self, run_dir: Path, figure_every: int = 50, render_every: int = 0):
        # the figure redraws the whole history with matplotlib: on a 2-core VM, a 300-generation
        # four-niche run at 20 ticks took 162 s with a figure every 10 generations, 133 s every
        # 50; on a GPU a generation takes about 0.1 s, less than one figure
        self.run_dir = Path(run_dir)
        self.writer = None
        self.figure_every = max(1, figure_every)
        self.render_every = render_every
        self._figure_step: int | None = None  # the generation of the last figure drawn

    def on_start(self, ev: Evolution) -> None:
        # on a resume, events of the generations the run computes again (those from its
        # checkpoint on) are purged: TensorBoard shows each generation once
        from torch.utils.tensorboard import SummaryWriter

        gen = ev.state.generation
        self.writer = SummaryWriter(log_dir=str(self.run_dir), purge_step=gen if gen else None)
        self.writer.add_text("config", config_markdown(ev), gen)
        self.writer.add_custom_scalars(custom_scalars_layout())
        file_writer = self.writer._get_file_writer()
        for s in hparams_summaries(ev):
            file_writer.add_summary(s, gen)

    def on_generation(self, ev: Evolution, result: GenerationResult) -> None:
        step = result.generation
        row = scalars(result)
        for tag in SCALAR_TAGS:
            v = row[tag]
            self.writer.add_scalar(tag, float(v) if v is not None else math.nan, step)
        for tag, v in best_scalars(result).items():
            self.writer.add_scalar(tag, v, step)
        for tag, name in HISTOGRAMS.items():
            self.writer.add_histogram(tag, getattr(result, name), step)
        if step % self.figure_every == 0:
            self._figure(ev, step)
        if self.render_every and step % self.render_every == 0:
            img = replay_strip(ev, result.team["designs"], seed=step)
            self.writer.add_image("team/replay", img, step, dataformats="HWC")
        self.writer.flush()

    def _figure(self, ev: Evolution, step: int) -> None:
        if ev.state.history:
            img = figure_image(composition_figure(ev.state.history))
            self.writer.add_image("species/composition", img, step, dataformats="HWC")
            self._figure_step = step

    def on_end(self, ev: Evolution) -> None:
        if self.writer is None:
            return
        if ev.state.history:
            step = ev.state.history[-1]["generation"]
            if self._figure_step != step:  # the last generation's figure, once
                self._figure(ev, step)
            best = app_record(ev).best
            if self.render_every and best and best.get("designs"):
                img = replay_strip(ev, best["designs"], seed=step)
                self.writer.add_image("best/replay", img, step, dataformats="HWC")
        self.close()

    def close(self) -> None:
        """Flush and close the event file (its writer thread ends)."""
        if self.writer is not None:
            self.writer.close()
