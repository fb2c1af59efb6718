"""The species-composition figure: its legend names the largest species by the ids `inspect`
prints; `evolve --figure-every N` sets its cadence in TensorBoard, and every run ends with one."""

from pathlib import Path

from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
from typer.testing import CliRunner

from swarmcode_torch.app.cli import app
from swarmcode_torch.app.reporting import composition_figure

TINY = [
    "--scenario",
    "one-niche",
    "--population",
    "6",
    "--swarm-size",
    "3",
    "--trials",
    "1",
    "--ticks",
    "6",
    "--seed",
    "3",
    "--device",
    "cpu",
    "--no-compile",
    "--render-every",
    "0",
]


def _legend(ax) -> tuple[str, list[str]]:
    leg = ax.get_legend()
    return leg.get_title().get_text(), [t.get_text() for t in leg.get_texts()]


def test_the_legend_names_the_largest_species_largest_first():
    history = [
        {"generation": g, "population": {3: 10 - g, 7: g, 12: 1, 40: 2}, "team": {"7": 4, "3": 1}}
        for g in range(4)
    ]
    fig = composition_figure(history, legend=2)
    pop, team = fig.axes[0], fig.axes[1]
    # population totals over the 4 generations: 3 -> 34, 7 -> 6, 40 -> 8, 12 -> 4
    assert _legend(pop) == ("species\n(+2 more)", ["3", "40"])
    assert _legend(team) == ("species", ["7", "3"])
    assert composition_figure(history, legend=0).axes[0].get_legend() is None
    assert _legend(composition_figure(history).axes[0])[1] == ["3", "40", "7", "12"]


def _figure_steps(run_dir: Path) -> list[int]:
    acc = EventAccumulator(str(run_dir), size_guidance={"images": 0})
    acc.Reload()
    return [e.step for e in acc.Images("species/composition")]


def test_figure_every_sets_the_cadence_and_the_last_generation_gets_one(tmp_path):
    r = CliRunner().invoke(
        app,
        [
            "evolve",
            *TINY,
            "--generations",
            "5",
            "--figure-every",
            "3",
            "--logdir",
            str(tmp_path / "a"),
        ],
    )
    assert r.exit_code == 0, r.output
    (run,) = (tmp_path / "a").iterdir()
    assert _figure_steps(run) == [0, 3, 4]
    # the default cadence (50) in a shorter run: the first and the last generation
    r = CliRunner().invoke(
        app, ["evolve", *TINY, "--generations", "3", "--logdir", str(tmp_path / "b")]
    )
    assert r.exit_code == 0, r.output
    (run,) = (tmp_path / "b").iterdir()
    assert _figure_steps(run) == [0, 2]
    r = CliRunner().invoke(
        app, ["evolve", *TINY, "--figure-every", "0", "--logdir", str(tmp_path / "c")]
    )
    assert r.exit_code == 2 and "--figure-every" in r.output and not (tmp_path / "c").exists()


def test_figure_every_is_in_the_help():
    r = CliRunner().invoke(app, ["evolve", "--help"], env={"COLUMNS": "200"})
    assert "--figure-every" in r.output and "end of every run" in r.output
