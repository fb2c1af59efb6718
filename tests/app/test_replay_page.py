"""The interactive replay page (`replay --html`): teams, data, the file (no browser here;
tests/e2e/test_replay_browser.py drives Chromium)."""

import base64
import hashlib
import json
import re
from pathlib import Path

import pytest
import torch
from replaykit import DESIGNS, design
from typer.testing import CliRunner

from swarmcode_torch.app.analysis import replay_run
from swarmcode_torch.app.cli import app
from swarmcode_torch.app.episodes import divergence, record_episode
from swarmcode_torch.app.render import team_genome
from swarmcode_torch.app.replay_explain import design_credits, explain_lines, seed_marginals
from swarmcode_torch.app.replay_page import decode_page, final_counts, page_data, render_html
from swarmcode_torch.app.replay_teams import focal_and_baseline
from swarmcode_torch.app.runs import write_config
from swarmcode_torch.coevo.config import SwarmCoDeConfig
from swarmcode_torch.coevo.evaluation import simulate_teams, team_scores
from swarmcode_torch.coevo.fitness import raw_fitness, raw_fitness_terms
from swarmcode_torch.sim import bt
from swarmcode_torch.sim.layout import make_layouts
from swarmcode_torch.sim.runtime import tick_function
from swarmcode_torch.sim.scenario import load_scenario
from swarmcode_torch.sim.state import WorldParams


@pytest.fixture(scope="module")
def two_niche():
    cfg = SwarmCoDeConfig(scenario="two-niche")
    return page_data(DESIGNS, load_scenario("two-niche"), cfg, seed=1), cfg


# ------------------------------------------------------------------ teams
def test_focal_is_the_largest_design_and_its_slots_are_refilled_by_partners():
    focal, team, base, recorded = focal_and_baseline(DESIGNS, seed=4)
    assert not recorded
    assert focal == 0 and team.tolist() == [0] * 12 + [1] * 6 + [2] * 2
    assert torch.equal(base[12:], team[12:])  # partner slots stay
    assert set(base[:12].tolist()) <= {1, 2} and len(set(base[:12].tolist())) == 2
    again = focal_and_baseline(DESIGNS, seed=4)[2]
    assert torch.equal(base, again)  # deterministic from the seed
    draws = torch.cat([focal_and_baseline(DESIGNS, seed=s)[2][:12] for s in range(30)])
    # by dominance: design 2 (0.9) drawn about 0.9 / 1.1 of the time
    assert 0.7 < float((draws == 2).float().mean()) < 0.95


def test_a_record_that_names_its_focal_and_a_team_without_partners():
    marked = [dict(d) for d in DESIGNS]
    marked[2]["focal"] = True
    focal, team, base, _ = focal_and_baseline(marked, seed=0)
    assert focal == 2 and set(base[18:].tolist()) <= {0, 1} and torch.equal(base[:18], team[:18])
    focal, team, base, _ = focal_and_baseline(DESIGNS[:1], seed=0)
    assert focal == 0 and (base == -1).all()  # no partner: no robot
    # equal counts: the first design
    assert focal_and_baseline([design(count=2), design(count=2, species=5)])[0] == 0


def test_a_record_with_its_baseline_counts_gives_that_baseline():
    rec = [
        dict(d, focal=i == 1, baseline_count=b) for i, (d, b) in enumerate(zip(DESIGNS, (15, 0, 5)))
    ]
    focal, team, base, recorded = focal_and_baseline(rec, seed=0)
    assert recorded and focal == 1
    assert torch.equal(base[:12], team[:12]) and torch.equal(base[18:], team[18:])
    assert sorted(base[12:18].tolist()) == [0, 0, 0, 2, 2, 2]
    # counts that do not fit the team: reconstructed instead
    bad = [
        dict(d, focal=i == 1, baseline_count=b) for i, (d, b) in enumerate(zip(DESIGNS, (15, 0, 1)))
    ]
    assert focal_and_baseline(bad, seed=0)[3] is False
    alone = [dict(DESIGNS[0], focal=True, baseline_count=0)]
    f, team, base, recorded = focal_and_baseline(alone)
    assert recorded and (base == -1).all()


def test_evolution_records_the_focal_design_and_its_baseline_team():
    from swarmcode_torch.app.api import evolve

    res = evolve(
        scenario="two-niche",
        generations=2,
        population=8,
        swarm_size=6,
        trials=1,
        ticks=10,
        seed=0,
        logdir=None,
        device="cpu",
        compile=False,
    )
    for d in res.best_team["designs"]:
        assert isinstance(d["focal"], bool) and isinstance(d["baseline_count"], int)
    assert sum(d["focal"] for d in res.best_team["designs"]) == 1
    f, team, base, recorded = focal_and_baseline(res.best_team["designs"])
    assert recorded and base.numel() == 6


# ------------------------------------------------------------------ data
def test_page_counts_equal_episode_metrics_of_the_evaluation_rollout(two_niche):
    data, cfg = two_niche
    s = load_scenario("two-niche")
    genome, _ = team_genome(DESIGNS, cfg.tag_length)
    _, team, base, _ = focal_and_baseline(DESIGNS, seed=1)
    # the evaluation's own rollout of both teams in the page's environment, on the CPU's tick
    # (the fused tick where it builds), as a run evaluates them and the page records them
    layouts = make_layouts(
        s.__class__(**{**s.__dict__, "num_robots": 20}), 1, torch.Generator().manual_seed(1)
    )
    m = simulate_teams(
        torch.stack([team, base]),
        genome,
        bt.build_tables(genome.bt),
        torch.zeros(2, dtype=torch.long),
        layouts,
        WorldParams.for_scenario(s),
        s.episode_ticks,
        catalog=s.hardware,
        step_fn=tick_function(torch.device("cpu"), compile=False)[0],
    )
    assert float(m["delivered_individual"][0]) > 0  # a meaningful episode
    for k, name in enumerate(("focal", "baseline")):
        counts = final_counts(data, name)
        page_m = data["panels"][name]["metrics"]
        for key in (
            "delivered_individual",
            "delivered_collab",
            "picked_individual",
            "picked_collab",
        ):
            assert counts[key] == page_m[key] == float(m[key][k]), (name, key)
        assert counts["energy_used"] == pytest.approx(float(m["energy_used"][k]), abs=1e-4)
        assert page_m["energy_used"] == pytest.approx(float(m["energy_used"][k]), abs=1e-5)


def test_scores_terms_and_marginal(two_niche):
    data, cfg = two_niche
    ecfg = cfg.evaluation(20, 200)
    for name in ("focal", "baseline"):
        p = data["panels"][name]
        mt = {k: torch.tensor([v]) for k, v in p["metrics"].items()}
        terms = raw_fitness_terms(mt, ecfg.weights)
        assert p["terms"] == {k: pytest.approx(float(v[0]), rel=1e-5) for k, v in terms.items()}
        assert max(p["raw"], p["floor"]) == pytest.approx(
            float(raw_fitness(mt, ecfg.weights)[0]), rel=1e-5
        )
        assert p["score"] == pytest.approx(
            float(team_scores(mt, torch.tensor([p["cost"]]), ecfg)[0]), rel=1e-5
        )
    assert data["marginal"] == pytest.approx(
        data["panels"]["focal"]["score"] - data["panels"]["baseline"]["score"], abs=1e-5
    )
    # cost: robots plus the species overhead (the baseline has the partners' species only)
    assert data["panels"]["focal"]["species"] == 3 and data["panels"]["baseline"]["species"] == 2


def test_every_tick_of_every_robot_has_the_trace_of_its_tree(two_niche):
    data, _ = two_niche
    N, T = data["robots"], data["ticks"]
    tables = [bt.build_tables(torch.tensor([d["ops"]])) for d in data["designs"]]
    for name in ("focal", "baseline"):
        p = data["panels"][name]
        assert len(p["combo"]) == N * T and len(p["holding"]) == N * (T + 1)
        pairs = {(p["robots"]["design"][i % N], c) for i, c in enumerate(p["combo"]) if c >= 0}
        for r, c in sorted(pairs):
            d = data["designs"][r]
            acting, visited = d["traces"][str(c)]
            action, _, status = bt.lookup(tables[r], torch.tensor(0), bt.combo_statuses()[c])
            assert visited[-1] == [-1, int(status)]
            if int(status) == bt.RUNNING:
                assert d["ops"][acting] == int(action)
    # tree lines are `inspect`'s
    for d in data["designs"]:
        assert "\n".join(t for t, _ in d["tree"]) == bt.format_tree(d["ops"], root=True)


def test_the_page_credits_each_robot_and_names_the_tick_the_arenas_part(two_niche):
    data, cfg = two_niche
    designs = data["designs"]
    for name in ("focal", "baseline"):
        p = data["panels"][name]
        assert p["tick_mode"] in ("fused", "eager")
        c = [p["credits"][i : i + 4] for i in range(0, len(p["credits"]), 4)]
        assert all(0 < t <= data["ticks"] and p["robots"]["design"][r] >= 0 for t, r, _, _ in c)
        per = design_credits(data, name)
        # the individual packages' credits, summed over robots or designs, are the metrics
        assert sum(k == 0 for *_, k in c) == sum(d[0] for d in per)
        assert sum(d[0] for d in per) == p["metrics"]["delivered_individual"]
        assert sum(d[2] for d in per) == p["metrics"]["picked_individual"]
        assert len({q for _, _, q, k in c if k == 1}) == p["metrics"]["delivered_collab"]
        for d, row in enumerate(per):  # only robots of a design earn its credits
            if not any(x == d for x in p["robots"]["design"]):
                assert row == [0, 0, 0, 0]
    assert sum(d[0] for d in design_credits(data, "focal")) > 0  # a meaningful episode
    # the arenas part where a robot of a slot both teams share stands apart: episodes.divergence
    genome, _ = team_genome(DESIGNS, cfg.tag_length)
    _, team, base, _ = focal_and_baseline(DESIGNS, seed=1)
    s = load_scenario("two-niche")
    a, b = (record_episode(genome, t, s, 1) for t in (team, base))
    shared = (team == base) & (team >= 0)
    assert data["shared_slots"] == int(shared.sum()) == 8
    t, slot = divergence(a, b, shared)
    assert data["divergence"] == {"tick": t, "robot": slot}
    assert 0 < t < data["ticks"] and designs[team[slot]]["focal"] is False
    lines = explain_lines(data)
    assert f"The arenas part at tick {t} of {data['ticks']}: robot {slot} " in lines[0]
    assert lines[1].startswith("Focal arena, by design: ") and "delivered" in lines[1]


def test_the_marginal_over_several_environments_starts_with_the_pages_own(two_niche):
    data, cfg = two_niche
    assert data["seed_marginals"] is None  # one environment unless asked
    sm = seed_marginals(DESIGNS, load_scenario("two-niche"), cfg, seed=1, seeds=3)
    assert sm["seeds"] == [1, 3] and len(sm["marginal"]) == 3
    # the first environment is the page's: the same episodes, the same scores (one batch or not)
    assert sm["focal"][0] == pytest.approx(data["panels"]["focal"]["score"], abs=1e-5)
    assert sm["baseline"][0] == pytest.approx(data["panels"]["baseline"]["score"], abs=1e-5)
    assert sm["marginal"] == [f - b for f, b in zip(sm["focal"], sm["baseline"])]
    assert sm["mean"] == pytest.approx(sum(sm["marginal"]) / 3)
    assert sm["sd"] == pytest.approx(torch.tensor(sm["marginal"]).std().item(), rel=1e-6)
    # each environment is that of its seed: seed 2's first is the next one's (the focal's team
    # is the same; this record's baseline is drawn from the seed, so it may not be)
    again = seed_marginals(DESIGNS, load_scenario("two-niche"), cfg, seed=2, seeds=1)
    assert again["focal"] == sm["focal"][1:2] and again["sd"] is None


def test_the_file_is_self_contained_and_small(two_niche):
    data, _ = two_niche
    text = render_html(data)
    assert len(text.encode()) < 1_000_000  # 20 robots x 200 ticks
    assert not re.search(r"""(src|href)\s*=\s*["']?(https?:)?//""", text)
    assert "<link" not in text and "import(" not in text and "fetch(" not in text
    assert text.count("<script") == 2 and "/*SCRIPT*/" not in text and "@DATA@" not in text
    assert decode_page(text) == json.loads(json.dumps(data))


def test_swarm200_page_stays_small():
    s = load_scenario("swarm200")
    designs = [
        design("pincher", 0.3, count=150, species=1),
        design("suction", 0.3, count=50, program="forage_random", species=2),
    ]
    data = page_data(designs, s, SwarmCoDeConfig(scenario="swarm200"), seed=0, ticks=60)
    per_tick = len(render_html(data).encode()) / 60
    assert per_tick * s.episode_ticks < 4_000_000, per_tick  # the whole episode: a few MB
    assert final_counts(data, "focal")["energy_used"] == pytest.approx(
        data["panels"]["focal"]["metrics"]["energy_used"], abs=1e-4
    )


# ------------------------------------------------------------------ command and API
def _run(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    write_config(run, SwarmCoDeConfig(scenario="two-niche", ticks=30))
    (run / "summary.json").write_text(
        json.dumps({"designs": DESIGNS, "best_fitness": 12.5, "best_generation": 4})
    )
    (run / "teams.jsonl").write_text(
        json.dumps({"generation": 2, "fitness": 3.0, "designs": DESIGNS[:2]}) + "\n"
    )
    return run


def test_replay_run_html_and_the_command(tmp_path):
    run = _run(tmp_path)
    path, m = replay_run(run, html=True)
    assert path == run / "team.html" and path.is_file()
    data = decode_page(path.read_text())
    assert data["ticks"] == 30 and data["record"] == {
        "run": "run",
        "fitness": 12.5,
        "generation": 4,
    }
    assert m == data["panels"]["focal"]["metrics"] or all(
        m[k] == pytest.approx(v, abs=1e-5) for k, v in data["panels"]["focal"]["metrics"].items()
    )
    res = CliRunner().invoke(
        app,
        [
            "replay",
            str(run),
            "--html",
            "--generation",
            "2",
            "--out",
            str(tmp_path / "g2.html"),
            "--ticks",
            "12",
            "--seed",
            "3",
        ],
    )
    assert res.exit_code == 0, res.output
    data = decode_page((tmp_path / "g2.html").read_text())
    # the command says where the arenas part and who delivered, as the page does
    for line in explain_lines(data):
        assert line in " ".join(res.output.split()), line
    # --seeds N: the marginal over N environments, printed and on the page
    res = CliRunner().invoke(
        app,
        [
            "replay",
            str(run),
            "--html",
            "--ticks",
            "12",
            "--seeds",
            "3",
            "--out",
            str(tmp_path / "s.html"),
        ],
    )
    assert res.exit_code == 0, res.output
    sm = decode_page((tmp_path / "s.html").read_text())["seed_marginals"]
    assert sm["seeds"] == [0, 2] and len(sm["marginal"]) == 3
    assert f"Marginal contribution over 3 environments (seeds 0-2): mean {sm['mean']:.1f}" in (
        " ".join(res.output.split())
    )
    res = CliRunner().invoke(app, ["replay", str(run), "--seeds", "0"])
    assert res.exit_code == 2 and "seeds must be an integer in [1, 1000], got 0" in res.output
    assert "Traceback" not in res.output
    assert data["ticks"] == 12 and data["seed"] == 3 and len(data["designs"]) == 2
    assert data["record"]["generation"] == 2 and data["record"]["fitness"] == 3.0
    # the GIF stays the default
    res = CliRunner().invoke(app, ["replay", str(run), "--ticks", "4"])
    assert res.exit_code == 0 and (run / "team.gif").is_file()
    assert "By design: species 3 (12 robots): " in " ".join(res.output.split())


def test_html_into_a_missing_folder_or_a_directory_is_one_line(tmp_path):
    run = _run(tmp_path)
    for out, msg in (
        (tmp_path / "nope" / "t.html", "does not exist"),
        (tmp_path, "is a directory"),
    ):
        res = CliRunner().invoke(app, ["replay", str(run), "--html", "--out", str(out)])
        assert res.exit_code != 0 and msg in res.output and "Traceback" not in res.output
    assert (
        "team.html"
        in CliRunner().invoke(app, ["replay", str(run), "--html", "--out", str(tmp_path)]).output
    )


def test_a_team_of_one_design_has_an_empty_baseline():
    data = page_data(
        DESIGNS[:1],
        load_scenario("one-niche"),
        SwarmCoDeConfig(scenario="one-niche"),
        seed=0,
        ticks=20,
    )
    base = data["panels"]["baseline"]
    assert set(base["robots"]["design"]) == {-1} and base["species"] == 0
    assert set(base["combo"]) == {-1} and final_counts(data, "baseline")["picked_individual"] == 0
    assert data["marginal"] == pytest.approx(data["panels"]["focal"]["score"] - base["score"])


def test_a_planted_best_generation_reaches_the_page_as_nothing_but_a_number(tmp_path):
    """summary.json's best_generation and best_fitness go into the page's record only as numbers
    (a planted script in them is dropped), and the page carries a policy naming its own script."""
    run = _run(tmp_path)
    planted = "<img src=x onerror=alert(1)>"
    (run / "summary.json").write_text(
        json.dumps({"designs": DESIGNS, "best_fitness": planted, "best_generation": planted})
    )
    path, _ = replay_run(run, html=True, ticks=3)
    text = path.read_text()
    assert planted not in text and decode_page(text)["record"] == {"run": "run"}
    csp = re.search(r'http-equiv="Content-Security-Policy" content="([^"]+)"', text).group(1)
    script = text[text.rindex("<script>") + len("<script>") : text.rindex("</script>")]
    digest = base64.b64encode(hashlib.sha256(script.encode()).digest()).decode()
    assert f"script-src 'sha256-{digest}'" in csp and "unsafe-inline" not in csp.split(";")[1]


@pytest.mark.parametrize("html", [False, True])
def test_replay_refuses_a_link_or_a_device_as_its_output(tmp_path, html):
    """--out onto a device node (/dev/null) or a planted symlink is refused in one line; the node
    and the link's target are left as they were."""
    run = _run(tmp_path)
    target = tmp_path / "elsewhere.txt"
    target.write_text("keep")
    name = "team.html" if html else "team.gif"
    (run / name).symlink_to(target)
    flags = ["--html"] if html else []
    for out in (None, "/dev/null"):
        args = ["replay", str(run), "--ticks", "3", *flags] + (["--out", out] if out else [])
        res = CliRunner().invoke(app, args)
        assert res.exit_code != 0 and "Traceback" not in res.output, res.output
        assert ("symbolic link" if out is None else "not a regular file") in res.output
    assert target.read_text() == "keep" and (run / name).is_symlink()
    assert Path("/dev/null").is_char_device()
