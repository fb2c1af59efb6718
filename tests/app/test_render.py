"""Replays: team genomes from summary designs, recorded episodes, GIF / PNG / image export."""

import json

import numpy as np
import pytest
import torch
from PIL import Image

from swarmcode_torch.app.analysis import replay_run
from swarmcode_torch.app.frames import frame_image, save_gif, save_png
from swarmcode_torch.app.render import Episode, record_episode, team_genome
from swarmcode_torch.app.runs import write_config
from swarmcode_torch.coevo.config import SwarmCoDeConfig
from swarmcode_torch.coevo.population import PINCHER, SUCTION
from swarmcode_torch.sim import bt
from swarmcode_torch.sim.scenario import load_scenario
from swarmcode_torch.sim.state import HELD


def design(effector="pincher", radius=0.4, tiers=(3, 3, 3), count=3, program="forage", **kw):
    d = dict(
        species=1,
        effector=effector,
        radius=radius,
        chassis_tier=tiers[0],
        battery_tier=tiers[1],
        motor_tier=tiers[2],
        torque_point=1.0,
        battery_point=1.0,
        dominance=0.6,
        selectivity=0.3,
        cost=123.0,
        bt=bt.template_tensor(program, 32).tolist(),
        count=count,
    )
    d.update(kw)
    return d


DESIGNS = [
    design("pincher", 0.42, (3, 2, 3), count=4),
    design("suction", 0.2, (1, 3, 2), count=2, program="forage_random", species=7),
]


def test_team_genome_round_trip():
    g, team = team_genome(DESIGNS, tag_length=8)
    assert g.size == 2 and g.tag.shape == (2, 8) and not g.tag.any()
    assert team.tolist() == [0, 0, 0, 0, 1, 1]
    assert g.effector.tolist() == [PINCHER, SUCTION]
    assert (
        g.chassis.tolist() == [2, 0] and g.battery.tolist() == [1, 2] and g.motor.tolist() == [2, 1]
    )
    assert torch.allclose(g.radius, torch.tensor([0.42, 0.2]))
    assert g.bt.shape == (2, 32) and g.bt[1].tolist() == DESIGNS[1]["bt"]
    assert torch.allclose(g.dominance, torch.tensor([0.6, 0.6]))


def test_team_genome_rejects_bad_designs():
    with pytest.raises(ValueError, match="effector"):
        team_genome([design(effector="magnet")])
    with pytest.raises(ValueError, match="radius"):
        team_genome([{k: v for k, v in design().items() if k != "radius"}])
    with pytest.raises(ValueError):
        team_genome([])


def test_snapshot_count_and_ticks():
    g, team = team_genome(DESIGNS)
    ep = record_episode(g, team, load_scenario("one-niche"), seed=1, ticks=10, every=3)
    assert [int(s.t) for s in ep.snapshots] == [0, 3, 6, 9, 10]
    assert ep.snapshots[0].pos.shape == (6, 2)
    assert set(ep.metrics) >= {"delivered_individual", "energy_used"}
    assert all(isinstance(v, float) for v in ep.metrics.values())


@pytest.fixture(scope="module")
def forage_episode() -> Episode:
    g, team = team_genome([design("pincher", 0.4, count=6)])
    return record_episode(g, team, load_scenario("one-niche"), seed=0, ticks=120, every=1)


def test_carried_packages_move_with_their_carriers(forage_episode):
    ep = forage_episode
    start = ep.layout.p_pos[0]
    carried = 0
    for s in ep.snapshots:
        for i in torch.nonzero(s.holding >= 0).flatten().tolist():
            p = int(s.holding[i])
            assert int(s.p_status[p]) == HELD and int(s.holder[p, 0]) == i
            assert torch.allclose(s.p_pos[p], s.pos[i], atol=1e-5)
            carried += bool((s.p_pos[p] - start[p]).norm() > 0.05)
    assert carried > 0, "no package was carried away from where it lay"


def test_frame_image_and_png(forage_episode, tmp_path):
    img = frame_image(forage_episode, 60)
    assert img.dtype == np.uint8 and img.ndim == 3 and img.shape[2] == 3
    assert img.shape[0] > 200 and img.shape[1] > 200
    assert img.min() < 50 and img.max() > 200  # something is drawn on a white background
    path = save_png(forage_episode, tmp_path / "f.png")
    with Image.open(path) as im:
        assert im.format == "PNG"


def test_robots_show_their_effector_and_light_packages_are_not_grip_white():
    from matplotlib.figure import Figure

    from swarmcode_torch.app.render import _mass_colors, draw_frame

    g, team = team_genome(DESIGNS)  # 4 pinchers, 2 suction robots
    ep = record_episode(g, team, load_scenario("budget"), seed=2, ticks=4, every=2)
    ax = Figure().add_subplot()
    draw_frame(ax, ep, ep.snapshots[0])
    (marks,) = [c for c in ax.collections if c.get_zorder() == 4.5]
    assert all(c[3] == 0 for c in marks.get_facecolor())  # outlines, over the robot colour
    corners = sorted(len(path.vertices) for path in marks.get_paths())
    assert corners[:4] == [5] * 4 and min(corners[4:]) > 8  # 4 squares (pincher), 2 rings
    # the legend shows each design with its mark
    legend = ax.get_legend()
    assert [t.get_text() for t in legend.get_texts()][:2] == ep.labels[:2]
    # the lightest package is a clear colour, not the white of a free grip marker
    lightest = min(
        _mass_colors(ep, ep.layout.p_mass[0][ep.layout.p_present[0]]), key=lambda c: -sum(c[:3])
    )
    assert sum(lightest[:3]) < 2.6 and lightest[2] < 0.7, lightest


def test_save_gif_frame_count(tmp_path):
    g, team = team_genome(DESIGNS)
    ep = record_episode(g, team, load_scenario("budget"), seed=2, ticks=6, every=2)
    path = save_gif(ep, tmp_path / "ep.gif", fps=5)
    with Image.open(path) as im:
        assert im.format == "GIF"
        assert im.n_frames == len(ep.snapshots) == 4
        assert im.info.get("duration") == 200


def test_replay_run(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    write_config(run, SwarmCoDeConfig(scenario="one-niche", ticks=5))
    (run / "summary.json").write_text(json.dumps({"designs": DESIGNS}))
    path, metrics = replay_run(run, ticks=4, every=2)
    assert path == run / "team.gif" and path.is_file()
    with Image.open(path) as im:
        assert im.n_frames == 3
    assert all(isinstance(v, float) for v in metrics.values())
    # one generation's best team comes from teams.jsonl; the last record of a generation wins
    lines = [{"generation": 3, "designs": DESIGNS}, {"generation": 3, "designs": DESIGNS[:1]}]
    (run / "teams.jsonl").write_text("\n".join(json.dumps(x) for x in lines) + "\n")
    path, _ = replay_run(run, out=tmp_path / "g3.gif", ticks=2, every=2, generation=3)
    assert path.is_file()
    with pytest.raises(ValueError, match="no record of generation 7"):
        replay_run(run, generation=7)


def test_frames_draw_each_robot_in_its_design_colour_where_it_stands():
    from swarmcode_torch.app.frames import FrameRenderer
    from swarmcode_torch.app.render import design_colors

    g, team = team_genome(DESIGNS)
    ep = record_episode(g, team, load_scenario("budget"), seed=2, ticks=40, every=20)
    cv = FrameRenderer(ep, dpi=100)
    colors = design_colors(2)
    for s in ep.snapshots:
        img = cv.render(s).astype(int)
        for i, (x, y) in enumerate(s.pos.tolist()):
            if int(s.holding[i]) >= 0:
                continue  # its package is drawn on top
            # the disc's fill between the centre mark and the rim (pixels of the reduced frame)
            px = (cv.ox + cv.sx * (x + 0.7 * float(ep.robots.radius[0, i]))) / 2
            py = (cv.h - (cv.oy + cv.sy * y)) / 2
            want = np.array(colors[int(team[i])][:3]) * 255
            got = img[int(round(py)), int(round(px))]
            assert np.abs(got - want).max() < 40, (int(s.t), i, got, want)


def test_a_gifs_frames_are_its_snapshots_drawn(tmp_path):
    g, team = team_genome(DESIGNS)
    ep = record_episode(g, team, load_scenario("budget"), seed=2, ticks=30, every=10)
    path = save_gif(ep, tmp_path / "ep.gif", fps=5)
    with Image.open(path) as im:
        frames = []
        for k in range(im.n_frames):
            im.seek(k)
            frames.append(np.asarray(im.convert("RGB")).astype(int))
    for k in range(len(ep.snapshots)):  # each frame is its snapshot, drawn
        assert np.abs(frames[k] - frame_image(ep, k)).mean() < 3
    assert np.abs(frames[0] - frames[-1]).max() > 100  # robots moved
