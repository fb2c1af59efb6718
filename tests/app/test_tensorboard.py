"""What a run shows in TensorBoard, read back from its event files: the Custom Scalars layout
names tags the run wrote, the Time Series groups put the species and team counts before the
gene histograms, every scalar has a point per generation (no one-point `hparams/*` cards), the
HParams tab lists the settings that matter and those that differ from the preset (not every
constant), and a run shorter than the replay interval still ends with its best team's replay."""

import re

import pytest
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
from typer.testing import CliRunner

from swarmcode_torch.app.cli import app
from swarmcode_torch.app.reporting import CUSTOM_SCALARS, HPARAM_METRICS, SCALAR_TAGS

GENERATIONS = 3
# the default --render-every (50) is longer than the run
RUN = [
    "evolve",
    "--scenario",
    "four-niche",
    "--population",
    "6",
    "--swarm-size",
    "4",
    "--trials",
    "1",
    "--ticks",
    "6",
    "--seed",
    "2",
    "--device",
    "cpu",
    "--no-compile",
    "--budget",
    "1500",
    "--set",
    "delta=0.5",
    "--generations",
    str(GENERATIONS),
]


@pytest.fixture(scope="module")
def acc(tmp_path_factory):
    logdir = tmp_path_factory.mktemp("tb")
    r = CliRunner().invoke(app, [*RUN, "--logdir", str(logdir)])
    assert r.exit_code == 0, r.output
    (run_dir,) = logdir.iterdir()
    acc = EventAccumulator(
        str(run_dir), size_guidance={"images": 0, "histograms": 0, "scalars": 0, "tensors": 0}
    )
    acc.Reload()
    return acc


def _layout(acc):
    from tensorboard.plugins.custom_scalar import layout_pb2, metadata
    from tensorboard.util import tensor_util

    events = acc.Tensors(metadata.CONFIG_SUMMARY_TAG)
    raw = tensor_util.make_ndarray(events[-1].tensor_proto).item()
    return layout_pb2.Layout.FromString(raw)


def test_custom_scalars_layout_names_tags_the_run_wrote(acc):
    layout = _layout(acc)
    scalars = acc.Tags()["scalars"]
    assert [c.title for c in layout.category] == list(CUSTOM_SCALARS)
    named = set()
    for category in layout.category:
        assert category.chart, category.title
        for chart in category.chart:
            assert chart.multiline.tag, chart.title
            for rx in chart.multiline.tag:
                hits = [t for t in scalars if re.search(rx, t)]
                assert len(hits) == 1, (chart.title, rx, hits)  # each names one written tag
                named.update(hits)
    assert {
        "species/count",
        "team/species",
        "team/niches",
        "best/niches",
        "fitness/best",
        "team/fitness",
        "team/cost",
        "team/budget",
        "best/cost",
    } <= named
    assert acc.Scalars("team/budget")[0].value == 1500.0


def _group(tag: str) -> str:
    return tag.split("/")[0]


def test_species_and_team_counts_come_before_the_histograms(acc):
    """The Time Series tab shows its groups (the tag before the first '/') in name order."""
    tags = acc.Tags()
    histograms = tags["histograms"]
    assert len(histograms) == 3
    groups = sorted({_group(t) for kind in ("scalars", "histograms", "images") for t in tags[kind]})
    first_histogram = min(groups.index(_group(t)) for t in histograms)
    for tag in ("species/count", "team/species", "team/niches", "best/species", "best/niches"):
        assert tag in tags["scalars"], tag
        assert groups.index(_group(tag)) < first_histogram, (tag, groups)


def test_every_scalar_has_a_point_per_generation(acc):
    """No scalar card of one or two points: the HParams metrics are the best team's scalars,
    written every generation, not separate `hparams/*` scalars written at the end."""
    scalars = acc.Tags()["scalars"]
    assert set(SCALAR_TAGS) | set(HPARAM_METRICS) == set(scalars)
    for tag in scalars:
        assert [e.step for e in acc.Scalars(tag)] == list(range(GENERATIONS)), tag
    assert not [t for t in scalars if t.startswith("hparams/")]
    best = acc.Scalars("best/fitness")
    assert all(a.value <= b.value for a, b in zip(best, best[1:]))  # the best so far


def test_hparams_lists_what_matters_and_what_differs_from_the_preset(acc):
    from tensorboard.plugins.hparams.plugin_data_pb2 import HParamsPluginData

    content = acc.PluginTagToContent("hparams")
    exp = HParamsPluginData.FromString(content["_hparams_/experiment"]).experiment
    start = HParamsPluginData.FromString(content["_hparams_/session_start_info"])
    hp = start.session_start_info.hparams
    names = [i.name for i in exp.hparam_infos]
    # the fixed keys, then the keys this run changed from the default preset (delta; and
    # --trials, --ticks, --device ... which set the run's size and where it computes)
    assert names[:8] == [
        "preset",
        "scenario",
        "budget",
        "objective",
        "seed",
        "population",
        "swarm_size",
        "generations",
    ]
    assert {"delta", "trials", "ticks", "device"} <= set(names[8:])
    assert not {"p_marginal", "alpha", "tag_length", "max_elite"} & set(names)  # constants
    assert len(names) < 16
    # TensorBoard shows the first five, those marked `differs` first, each part by name
    shown = sorted(exp.hparam_infos, key=lambda i: (not i.differs, i.name))[:5]
    assert [i.name for i in shown] == ["budget", "delta", "objective", "preset", "scenario"]
    assert hp["budget"].number_value == 1500 and hp["delta"].number_value == 0.5
    assert hp["swarm_size"].number_value == 4 and hp["scenario"].string_value == "four-niche"
    assert [m.name.tag for m in exp.metric_infos] == list(HPARAM_METRICS)
    assert set(HPARAM_METRICS) <= set(acc.Tags()["scalars"])


def test_a_run_shorter_than_the_replay_interval_ends_with_its_best_teams_replay(acc):
    assert [e.step for e in acc.Images("team/replay")] == [0]
    (end,) = acc.Images("best/replay")
    assert end.step == GENERATIONS - 1
    assert end.width > 3 * end.height > 0  # three frames side by side
