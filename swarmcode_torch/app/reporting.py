"""Reporting: TensorBoard (scalars, histograms, the species-composition figure, replays, the
Custom Scalars layout, the config and its hyperparameters), metrics.csv (every scalar, one row
per generation) and, optional, Weights & Biases (the same scalars, the config, the replays).

Matplotlib and TensorBoard are imported inside the functions that need them; figures are drawn
on `matplotlib.figure.Figure` with the Agg canvas, never through pyplot or a backend switch."""

from __future__ import annotations

import csv
import io
import math
import os
import re
import warnings
from pathlib import Path

from ..coevo.evolve import Evolution, GenerationResult
from .files import METRICS_FILE
from .records import HISTOGRAMS, SCALAR_TAGS, scalars


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


def composition_figure(history: list[dict], legend: int = 8):
    """A matplotlib `Figure`: species composition of the population and of the best team per
    generation (stacked areas, one colour per species id; paper Fig. 5). Each panel's legend
    names its `legend` largest species (most individuals, or robots, over the generations
    shown) by the ids `swarmcode-torch inspect` prints, largest first (0: no legend).

    Drawn object-oriented (`matplotlib.figure.Figure`): no pyplot, no backend change, so a
    notebook keeps its inline plots; the figure displays as the value of a cell
    (`IPython.display.display(fig)`) and `fig.savefig(path)` writes it."""
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
    import re

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

    from .render import frame_image, record_episode, team_genome

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


class TensorBoardReporter:
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
            best = ev.state.best
            if self.render_every and best and best.get("designs"):
                img = replay_strip(ev, best["designs"], seed=step)
                self.writer.add_image("best/replay", img, step, dataformats="HWC")
        self.close()

    def close(self) -> None:
        """Flush and close the event file (its writer thread ends)."""
        if self.writer is not None:
            self.writer.close()


class CsvReporter:
    """Appends every generation's scalars (`records.scalars`) to metrics.csv in the run directory:
    one row per generation, the header (`generation` and the tags) once; each row is written
    (unbuffered) when its generation ends. On a resume, rows of generations the run repeats (those after its checkpoint)
    are dropped first, so the file keeps one row per generation; a header that lacks some of
    the tags gets them (earlier rows leave them empty)."""

    def __init__(self, run_dir: Path):
        self.path = Path(run_dir) / METRICS_FILE
        self.columns: list[str] | None = None

    def on_start(self, ev: Evolution) -> None:
        if not self.path.is_file():
            return
        rows, columns = read_metrics_csv(self.path, raw=True)
        rows = [r for r in rows if r["generation"] < ev.state.generation]
        self._rewrite(columns, rows)

    def _rewrite(self, columns: list[str], rows: list[dict]) -> None:
        from .files import atomic_write_bytes

        buf = io.StringIO()
        w = csv.DictWriter(
            buf, fieldnames=columns, restval="", extrasaction="ignore", lineterminator="\n"
        )
        w.writeheader()
        for r in rows:
            w.writerow({k: ("" if v is None else v) for k, v in r.items()})
        atomic_write_bytes(self.path, buf.getvalue().encode())
        self.columns = list(columns)

    def on_generation(self, ev: Evolution, result: GenerationResult) -> None:
        row = {k: (int(v) if isinstance(v, bool) else v) for k, v in scalars(result).items()}
        if self.columns is None or not set(row) <= set(self.columns):
            old, _ = read_metrics_csv(self.path, raw=True) if self.path.is_file() else ([], [])
            self._rewrite(
                (self.columns or []) + [k for k in row if k not in (self.columns or [])], old
            )
        from .files import append_line

        buf = io.StringIO()
        csv.DictWriter(buf, fieldnames=self.columns, restval="", lineterminator="").writerow(
            {k: ("" if v is None else v) for k, v in row.items()}
        )
        append_line(self.path, buf.getvalue())  # one os.write: on disk when it returns

    def on_end(self, ev: Evolution) -> None:
        pass


def _number(text: str):
    if text == "":
        return None
    try:
        return int(text)
    except ValueError:
        return float(text)


def read_metrics_csv(path: Path, raw: bool = False) -> tuple[list[dict], list[str]]:
    """The rows of a metrics.csv (numbers as int or float, empty cells None; a last row cut
    short by an interruption is skipped; any other row with more or fewer cells than the header,
    or whose generation or a cell is not a number, is a RunError naming it) and its header. With
    `raw`, the cells other than `generation` are kept as text. The file is read without
    following a link and up to `files.MAX_RECORD_BYTES`; RunError naming the file for one that
    cannot be read, is not UTF-8 or not CSV, or whose header is not metrics.csv's (no
    `generation` column, or columns that are no tag: a resume would otherwise drop its rows)."""
    from .files import MAX_RECORD_BYTES, RunError, read_text

    text = read_text(path, MAX_RECORD_BYTES)
    try:
        reader = csv.DictReader(io.StringIO(text, newline=""))
        columns = list(reader.fieldnames or [])
        unknown = [c for c in columns if c != "generation" and c not in SCALAR_TAGS]
        if columns and ("generation" not in columns or unknown or len(set(columns)) < len(columns)):
            what = (
                f"unknown columns {', '.join(repr(c[:40]) for c in unknown[:5])}"
                if unknown
                else "no 'generation' column"
                if "generation" not in columns
                else "a column named twice"
            )
            raise RunError(
                f"{path}: not a metrics.csv header ({what}); restore the header or "
                "move the file away"
            )
        rows = []
        records = list(reader)
        for i, r in enumerate(records):
            if any(v is None for v in r.values()) and None not in r and i == len(records) - 1:
                continue  # fewer cells than the header in the last line: cut short by a kill
            problem = None
            if None in r:
                problem = "more cells than the header"
            elif any(v is None for v in r.values()):
                problem = "fewer cells than the header"
            else:
                try:
                    gen = int(r["generation"])
                    row = {k: (v if raw else _number(v)) for k, v in r.items()}
                except (KeyError, ValueError):
                    problem = (
                        f"generation {str(r.get('generation'))[:20]!r} or a cell is not a number"
                    )
            if problem is not None:
                # a damaged row inside the file: refused, so that a resume does not drop it
                raise RunError(
                    f"{path}: data row {i + 1} is damaged ({problem}); repair or remove that row, "
                    "or move the file away"
                )
            row["generation"] = gen
            rows.append(row)
    except csv.Error as e:
        raise RunError(f"{path}: malformed CSV ({e})") from None
    return rows, columns


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


def _wandb_run_id(run_dir: Path) -> str:
    """A W&B run id of a run directory: the same on every resume of it, so that its parts
    continue one W&B run."""
    import hashlib

    return hashlib.sha256(str(Path(run_dir).resolve()).encode()).hexdigest()[:16]


class WandbReporter:
    """Logs a run to Weights & Biases: the config (every key of config.toml), every
    generation's scalars under the TensorBoard tags (`records.SCALAR_TAGS` and the best team's,
    `HPARAM_METRICS`) and gene histograms, a replay of the generation's best team every
    `render_every` generations and one of the run's best team (`best/replay`) at its end (0:
    never); at its end, the run directory's checkpoint and replays as an artifact
    (`wandb_runs.log_run_files`). Steps are generations. The W&B run is named after the run directory, and its id is
    derived from it, so a resumed run continues its W&B run; `project`, `entity`, `mode`
    ("online", "offline", or None: wandb's default and WANDB_MODE) and any other `wandb.init`
    keyword (`init`) as wandb takes them. Needs the `wandb` package (`WANDB_INSTALL`), imported
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
        lines = [ln.strip() for ln in str(e).splitlines() if ln.strip()]
        why = f"{type(e).__name__}: {lines[0][:200]}" if lines else type(e).__name__
        warnings.warn(
            f"Weights & Biases logging stopped ({why}); the run goes on without it",
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
        best = ev.state.best
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
