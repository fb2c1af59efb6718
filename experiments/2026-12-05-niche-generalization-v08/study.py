"""The generalization study of issue 38: does the default keep every niche on worlds nobody
tuned for?

    python experiments/2026-12-05-niche-generalization-v08/study.py run --split train \
        --arms v07,v08 [--generations 300] [--seeds 0,1,2] [--workers 2] [--runs DIR]
    python experiments/2026-12-05-niche-generalization-v08/study.py table --split train
    python experiments/2026-12-05-niche-generalization-v08/study.py paired --split train \
        --arms v13,v14 [--base v07] [--seeds 0,1,2]

Worlds: `--split train` or `test` are the generator's study worlds of that split
(`swarmcode_torch.sim.worlds.study_worlds`, generator seeds 1000-1999 and 5000-5999); `--split builtin` is
one-, two- and four-niche. The train split is the one to look at and choose with; the test split
is run only to report an adopted change.

Arms: `v07` is the 0.7 default (`--set essential_floor=0 --set admission_basis=members`),
`v08` the quota floor of essential species alone, `v09` the floor and admission by elites,
`v10` the floor kept until a holder is gated as often as a substitute (`essential_below=0.5`)
with admission by elites, `v11` re-founding of dead partners (`refound_after=5`), `v12` far
substitutes demoted (`demote_far_after=100`), `v13` equal quotas until generation 30, `v14`
re-founding by design cell (`refound_after=5`, `refound_source=designs`), `v15` a quota floor
of 3 for the best team's species (`best_team_floor=3`), `v16` v13 and v15 together (v13 and v16 ran with the defect that made selection within a species
follow row order while shares were equal), `v13b` v13 with that fixed, `v17` knock-out credit for the best team's needed species (`knockout_credit=0.05`), `v18` a floor of 3 for those species instead (`knockout_floor=3`), `v19` offspring shares by the mean marginal contribution (`share_basis=marginal`), `v20` by fitness plus marginal (`share_basis=fitness+marginal`), `v21` by the marginal contribution per slot the design fills (`share_basis=marginal/slot`), `v22` substitute pairs of the best team demoted by knock-out (`knockout_pairs=0.05`), `v23` an explorer every 10 generations (`refound_after=10`, `refound_source=random`), `v24` the previous best team's species partners of every focal (`team_partners=true`), `v25` v24 with substitute pairs of the best team demoted by knock-out (`knockout_pairs=0.05`), `v26` v24 with only the best team's species whose knock-out costs it more than 5 % (`team_partners_margin=0.05`), `v27` v24 with the best team the fewest species within 0.1 % of the top (`best_team_tie=0.001`), `v28` the default with that best team (a diagnostic), `v29` v27 with a partner demoted as a substitute only after 6 generations above one half (`demote_after=6`), `v30` v27 with the admission's nearest partner of the same effector (`substitute_effector=true`), `paper` the paper preset (`--preset paper`). (v09 was run while the
code's defaults were its settings, as `[]`.) (The v07 and v08 runs of the train split were made with the code of commit
59bf1a5, whose defaults were those settings.)

Every run is a CLI run in its own process (`--workers` at a time, one torch thread each),
population 50, the world's swarm size, in `--runs` (default /tmp/niche-study-runs). The study
is resumable: a run whose measures are in `results/` is not run again, and a run directory
left by an interrupted run is resumed (`evolve --resume`). Each finished run's measures go to
`results/SPLIT/ARM/WORLD__sSEED.json`; `table` prints the tables RESULTS.md shows.

Measures of one run (the niche count is known by construction; nothing of it is fed back):
- covered: the package classes some design of the generation's best team can lift (teams.jsonl
  records each design's capability); a world's niches are kept when every class is covered.
- kept_last: every class covered in every one of the last 50 generations.
- team_species / population_species: medians over the last 50 generations.
- score: median best-team score over the last 50; `table` divides it by the best median score
  of any run of the same world (any arm, any seed).
- founded_after_100: species founded a generation from generation 100 on.
- losses: for each class once covered for 100 generations in a row, every later gap in its
  coverage longer than 5 generations (the best team is one sample a generation); lost_for_good
  counts gaps longer than 50 (or reaching the end after more than 50), refounded the others.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

HERE = Path(__file__).resolve().parent
LAST = 50
HOLD = 100
REFOUND = 50
NOISE_GAP = 5
def _sets(*settings: str) -> list[str]:
    """`--set K=V` for each setting."""
    return [a for kv in settings for a in ("--set", kv)]


#: the 0.7 default's settings, the base of every later arm
V07 = ("essential_floor=0", "admission_basis=members")
ARMS = {
    "v07": _sets(*V07),
    "v08": _sets("admission_basis=members"),
    "v09": _sets("essential_floor=3", "admission_basis=elites"),
    "v10": _sets("essential_floor=3", "admission_basis=elites", "essential_below=0.5"),
    "v11": _sets(*V07, "refound_after=5"),
    "v12": _sets(*V07, "demote_far_after=100"),
    "v13": _sets(*V07, "equal_quotas_until=30"),
    "v14": _sets(*V07, "refound_after=5", "refound_source=designs"),
    "v15": _sets(*V07, "best_team_floor=3"),
    "v16": _sets(*V07, "equal_quotas_until=30", "best_team_floor=3"),
    "v13b": _sets(*V07, "equal_quotas_until=30"),  # v13 with selection within species fixed
    "v17": _sets(*V07, "knockout_credit=0.05"),
    "v18": _sets(*V07, "knockout_credit=0.05", "knockout_floor=3"),
    "v19": _sets(*V07, "share_basis=marginal"),
    "v20": _sets(*V07, "share_basis=fitness+marginal"),
    "v21": _sets(*V07, "share_basis=marginal/slot"),
    "v22": _sets(*V07, "knockout_pairs=0.05"),
    "v23": _sets(*V07, "refound_after=10", "refound_source=random"),
    "v24": _sets(*V07, "team_partners=true"),
    "v25": _sets(*V07, "team_partners=true", "knockout_pairs=0.05"),
    "v26": _sets(*V07, "team_partners=true", "team_partners_margin=0.05"),
    "v27": _sets(*V07, "team_partners=true", "best_team_tie=0.001"),
    "v28": _sets(*V07, "best_team_tie=0.001"),  # a diagnostic: v07's evolution, another report
    "v29": _sets(*V07, "team_partners=true", "best_team_tie=0.001", "demote_after=6"),
    "v30": _sets(*V07, "team_partners=true", "best_team_tie=0.001", "substitute_effector=true"),
    "paper": ["--preset", "paper"],
}
BUILTIN = {"one-niche": 1, "two-niche": 2, "four-niche": 4}


#: The reach-checked splits (PLAN.md, "the generator's reach check"): world K of the split's
#: seeds and knobs drawn with the generator's default `min_reach`.
REACH_SPLITS = {"train-r": "train", "test-r": "test"}
SPLITS = ("train", "test", "builtin", *REACH_SPLITS)
#: (K, why) of each world K the generator refuses with the reach check (no draw of its seed
#: and knobs within reach): left out of the reach-checked split, and said so
REFUSED: dict[str, list[tuple[int, str]]] = {s: [] for s in REACH_SPLITS}


def _reach_worlds(split: str) -> list[dict]:
    """The worlds of a reach-checked split: where the default draws the old split's world K
    again (every niche within reach at the first draw), that world, whose results are the old
    split's ("results": the split folder they are in); else the world it draws instead, named
    study-SPLIT-K and written to worlds/SPLIT/."""
    from swarmcode_torch.sim.scenario import ScenarioError
    from swarmcode_torch.sim.worlds import STUDY_SPECS, generate_world, split_seeds, world_toml

    base = REACH_SPLITS[split]
    folder = HERE / "worlds" / split
    out = []
    for k, (old, spec) in enumerate(zip(worlds(base), STUDY_SPECS)):
        seed = split_seeds(base)[k]
        try:
            again = generate_world(seed, name=old["name"], **spec)
        except ScenarioError as e:  # refused: no world of these knobs within reach
            REFUSED[split].append((k, str(e)))
            continue
        if again.table == _table(old["path"]):
            out.append({**old, "results": base})
            continue
        w = generate_world(seed, name=f"study-{split}-{k:02d}", **spec)
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / f"{w.scenario.name}.toml"
        text = world_toml(w)
        if not path.exists() or path.read_text() != text:
            path.write_text(text)
        out.append({"name": w.scenario.name, "path": str(path), "niches": int(w.niches)})
    return out


def _table(path: str) -> dict:
    import tomllib

    return tomllib.loads(Path(path).read_text())


def worlds(split: str) -> list[dict]:
    """[{name, path, niches}] of a split; generated worlds are written to worlds/SPLIT/."""
    if split == "builtin":
        return [{"name": n, "path": n, "niches": k} for n, k in BUILTIN.items()]
    if split in REACH_SPLITS:
        return _reach_worlds(split)
    from swarmcode_torch.sim.worlds import study_worlds, world_toml

    out = []
    folder = HERE / "worlds" / split
    folder.mkdir(parents=True, exist_ok=True)
    for w in study_worlds(split):
        name = w.scenario.name
        path = folder / f"{name}.toml"
        text = world_toml(w)
        if not path.exists() or path.read_text() != text:
            path.write_text(text)
        out.append({"name": name, "path": str(path), "niches": int(w.niches)})
    return out


def measure(run: Path, niches: int) -> dict:
    from swarmcode_torch.app.checkpoints import load_checkpoint
    from swarmcode_torch.app.summary import read_teams

    teams = read_teams(run)
    ck = load_checkpoint(run)
    history = ck["history"]
    n_classes = None
    from swarmcode_torch.sim.scenario import load_scenario

    n_classes = len(load_scenario(str(run / "scenario.toml")).packages)
    gens = sorted(teams)
    end = gens[-1] + 1
    covered = {}
    for g in gens:
        cov = set()
        for d in teams[g]["designs"]:
            cov.update(int(c) for c in d.get("capability", []))
        covered[g] = cov
    tail = [g for g in gens if g >= end - LAST]
    all_classes = set(range(n_classes))
    kept_last = all(covered[g] >= all_classes for g in tail)
    team_species = statistics.median(teams[g]["species"] for g in tail)
    pop = {h["generation"]: len(h["population"]) for h in history}
    pop_species = statistics.median(pop[g] for g in tail if g in pop)
    score = statistics.median(teams[g]["fitness"] for g in tail)
    seen: set[int] = set()
    founded_after = 0
    for h in history:
        ids = {int(s) for s in h["population"]}
        if h["generation"] >= HOLD:
            founded_after += len(ids - seen)
        seen |= ids
    losses = []
    for c in sorted(all_classes):
        run_len, held, gap_start = 0, False, None
        for g in range(end):
            on = c in covered.get(g, set())
            if on:
                if held and gap_start is not None and g - gap_start > NOISE_GAP:
                    losses.append({"class": c, "from": gap_start, "gap": g - gap_start})
                gap_start = None
                run_len += 1
                held = held or run_len >= HOLD
            else:
                run_len = 0
                if gap_start is None:
                    gap_start = g
        if held and gap_start is not None and end - gap_start > NOISE_GAP:
            losses.append({"class": c, "from": gap_start, "gap": end - gap_start, "open": True})
    return {
        "generations": end,
        "classes": n_classes,
        "niches": niches,
        "classes_covered_last": statistics.median(len(covered[g] & all_classes) for g in tail),
        "kept_last": kept_last,
        "team_species": team_species,
        "population_species": pop_species,
        "score": score,
        "founded_after_100": founded_after / max(1, end - HOLD),
        "losses": losses,
        "lost_for_good": sum(1 for x in losses if x["gap"] > REFOUND),
        "refounded": sum(1 for x in losses if x["gap"] <= REFOUND and not x.get("open")),
    }


def _done(run: Path, generations: int) -> bool:
    try:
        s = json.loads((run / "summary.json").read_text())
    except (OSError, ValueError):
        return False
    return s.get("generation") == generations - 1 and (run / "checkpoint.pt").is_file()


def run_one(job: dict) -> str:
    out = Path(job["result"])
    if out.exists():
        return f"have {out.name}"
    run = Path(job["run"])
    env = dict(os.environ, OMP_NUM_THREADS="1")
    exe = ["swarmcode-torch"]
    if job.get("code"):  # the package of another checkout (a frozen copy of the code under test)
        env["PYTHONPATH"] = job["code"]
        exe = [sys.executable, "-m", "swarmcode_torch"]
    common = ["--threads", "1", "--generations", str(job["generations"])]
    if (run / "checkpoint.pt").is_file() and not _done(run, job["generations"]):
        cmd = [*exe, "evolve", "--resume", str(run), *common]
    elif _done(run, job["generations"]):
        cmd = None
    else:
        run.parent.mkdir(parents=True, exist_ok=True)
        cmd = [
            *exe,
            "evolve",
            "--scenario",
            job["path"],
            "--population",
            "50",
            "--seed",
            str(job["seed"]),
            "--device",
            "cpu",
            "--logdir",
            str(run.parent),
            "--render-every",
            "0",
            "--figure-every",
            "100000",
            "--checkpoint-every",
            "50",
            *job["arm_args"],
            *common,
        ]
    t0 = time.time()
    if cmd is not None:
        res = subprocess.run(cmd, env=env, capture_output=True, text=True)
        if res.returncode != 0:
            return f"FAILED {run.name}: {res.stderr.strip().splitlines()[-1:]}"
        if not run.exists():  # a new run: its directory is named by the CLI; find it
            made = sorted(
                (
                    p
                    for p in run.parent.iterdir()
                    if p.is_dir() and p.name != run.name and not p.name.startswith("study__")
                ),
                key=lambda p: p.stat().st_mtime,
            )
            made[-1].rename(run)
    m = measure(run, job["niches"])
    m.update(world=job["world"], seed=job["seed"], arm=job["arm"], seconds=round(time.time() - t0))
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(m, indent=1) + "\n")
    return f"done {out.parent.name}/{out.name} in {time.time() - t0:.0f} s"


def cmd_run(a) -> None:
    jobs = []
    runs = Path(a.runs)
    # world by world, seed by seed, the arms side by side: a partial study is paired
    only = set(a.worlds.split(",")) if a.worlds else None
    for w in worlds(a.split):
        if only is not None and w["name"] not in only:
            continue
        for seed in [int(s) for s in a.seeds.split(",")]:
            for arm in a.arms.split(","):
                key = f"{w['name']}__s{seed}"
                jobs.append(
                    {
                        "world": w["name"],
                        "path": w["path"],
                        "niches": w["niches"],
                        "seed": seed,
                        "arm": arm,
                        "arm_args": ARMS[arm],
                        "generations": a.generations,
                        "code": a.code,
                        # one folder per run, so that the CLI's new directory is the only one
                        "run": str(runs / w.get("results", a.split) / arm / key / f"study__{key}"),
                        "result": str(
                            HERE / "results" / w.get("results", a.split) / arm / f"{key}.json"
                        ),
                    }
                )
    t0 = time.time()
    with ThreadPoolExecutor(a.workers) as ex:
        for i, msg in enumerate(ex.map(run_one, jobs), 1):
            el = time.time() - t0
            print(f"[{i}/{len(jobs)}] {msg}  ({el / 60:.1f} min)", flush=True)


def load(split: str) -> list[dict]:
    """Every recorded run of a split; of a reach-checked split, its own runs and the old
    split's runs on the worlds it shares with it."""
    rows = []
    for p in sorted((HERE / "results" / split).glob("*/*.json")):
        rows.append(json.loads(p.read_text()))
    if split in REACH_SPLITS:
        shared = {w["name"] for w in worlds(split) if "results" in w}
        rows += [r for r in load(REACH_SPLITS[split]) if r["world"] in shared]
    return rows


def cmd_table(a) -> None:
    rows = load(a.split)
    if a.seeds:  # the runs of these seeds only (a paired comparison)
        keep = {int(x) for x in a.seeds.split(",")}
        rows = [r for r in rows if r["seed"] in keep]
    best: dict[str, float] = {}
    for r in rows:
        best[r["world"]] = max(best.get(r["world"], float("-inf")), r["score"])
    if a.split in REACH_SPLITS:  # the arms run on the split's own worlds (the relative
        # score still against the best run of any arm)
        mine = {p.name for p in (HERE / "results" / a.split).iterdir() if p.is_dir()}
        rows = [r for r in rows if r["arm"] in mine]
    arms = sorted({r["arm"] for r in rows})
    out = {}
    for k, why in REFUSED.get(a.split, []):
        print(f"world {k} refused by the generator: {why}")
    print(f"split {a.split}: {len({r['world'] for r in rows})} worlds")
    print(
        "| arm | runs | every niche kept, last 50 | best-team species = niches | "
        "lost for good after a 100-generation hold | median score / best run of the world |"
        " founded a generation after 100 |"
    )
    print("|---|---|---|---|---|---|---|")
    for arm in arms:
        rs = [r for r in rows if r["arm"] == arm]
        n = len(rs)
        kept = sum(r["kept_last"] for r in rs)
        eq = sum(r["team_species"] == r["niches"] for r in rs)
        lost = sum(r["lost_for_good"] > 0 for r in rs)
        rel = statistics.median(r["score"] / best[r["world"]] for r in rs)
        fnd = statistics.median(r["founded_after_100"] for r in rs)
        out[arm] = dict(runs=n, kept=kept, species_eq=eq, lost=lost, rel_score=rel, founded=fnd)
        print(
            f"| {arm} | {n} | {kept} ({kept / n:.0%}) | {eq} ({eq / n:.0%}) | {lost} | "
            f"{rel:.3f} | {fnd:.3f} |"
        )
    if a.runs_table:
        print("\n| world | niches | seed | " + " | ".join(arms) + " |")
        print("|---|---|---|" + "---|" * len(arms))
        keyed = {(r["world"], r["seed"], r["arm"]): r for r in rows}
        for w, s in sorted({(r["world"], r["seed"]) for r in rows}):
            cells = []
            for arm in arms:
                r = keyed.get((w, s, arm))
                cells.append(
                    "-"
                    if r is None
                    else f"{'K' if r['kept_last'] else 'lost'} sp {r['team_species']:g} "
                    f"{r['score']:.0f}"
                )
            n = next(r["niches"] for r in rows if r["world"] == w)
            print(f"| {w} | {n} | {s} | " + " | ".join(cells) + " |")
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=1) + "\n")


def _sign_p(gains: int, losses: int) -> float:
    """Two-sided exact sign test of `gains` against `losses` (ties dropped)."""
    n, k = gains + losses, min(gains, losses)
    if n == 0:
        return 1.0
    return min(1.0, 2 * sum(math.comb(n, i) for i in range(k + 1)) / 2**n)


def cmd_paired(a) -> None:
    """Each arm against `--base` run by run (the same world and seed): the runs it gains and
    loses on "every niche kept" and on "species = niches", with a sign test's p-value."""
    seeds = {int(x) for x in a.seeds.split(",")}

    rows = load(a.split)

    def runs(arm: str) -> dict:
        return {(d["world"], d["seed"]): d for d in rows if d["arm"] == arm and d["seed"] in seeds}

    tests = {
        "every niche kept": lambda d: bool(d["kept_last"]),
        "species = niches": lambda d: d["team_species"] == d["niches"],
    }
    base = runs(a.base)
    print(f"| arm | paired runs | {' | '.join(f'{t}: gained / lost (p)' for t in tests)} |")
    print("|---|---|" + "---|" * len(tests))
    for arm in a.arms.split(","):
        mine = runs(arm)
        keys = sorted(set(base) & set(mine))
        cells = []
        for test in tests.values():
            gain = sum(test(mine[k]) and not test(base[k]) for k in keys)
            loss = sum(test(base[k]) and not test(mine[k]) for k in keys)
            cells.append(f"{gain} / {loss} ({_sign_p(gain, loss):.2f})")
        print(f"| {arm} | {len(keys)} | {' | '.join(cells)} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("--split", choices=SPLITS, required=True)
    r.add_argument("--arms", default="v08")
    r.add_argument("--seeds", default="0,1,2")
    r.add_argument("--generations", type=int, default=300)
    r.add_argument("--workers", type=int, default=2)
    r.add_argument("--runs", default="/tmp/niche-study-runs")
    r.add_argument("--code", help="run the package of this checkout (PYTHONPATH)")
    r.add_argument("--worlds", help="only these worlds of the split, e.g. two-niche")
    t = sub.add_parser("table")
    t.add_argument("--split", choices=SPLITS, required=True)
    t.add_argument("--runs-table", action="store_true")
    t.add_argument("--seeds", help="only the runs of these seeds, e.g. 0")
    t.add_argument("--json")
    p = sub.add_parser("paired")
    p.add_argument("--split", choices=SPLITS, required=True)
    p.add_argument("--arms", required=True)
    p.add_argument("--base", default="v07")
    p.add_argument("--seeds", default="0,1,2")
    a = ap.parse_args()
    {"run": cmd_run, "table": cmd_table, "paired": cmd_paired}[a.cmd](a)


if __name__ == "__main__":
    sys.exit(main())
