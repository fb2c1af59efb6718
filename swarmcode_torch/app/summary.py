"""summary.json and teams.jsonl: written every generation (`SummaryReporter`) and read back
with every field checked."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from ..coevo.evolve import Evolution, GenerationResult
from ..sim.bt import NUM_OPCODES
from ..sim.hardware import MAX_NESTING, nesting_depth
from ..sim.scenario import MAX_PACKAGES
from . import records
from .files import (
    MAX_RECORD_BYTES,
    SUMMARY_FILE,
    TEAMS_FILE,
    RunError,
    append_line,
    atomic_write_bytes,
    check_nesting,
    prepare_run_dir,
    read_text,
    trim_teams,
)
from .reporter import Reporter


class SummaryReporter(Reporter):
    """Rewrites summary.json (atomically) after every generation and appends the generation's
    best team to teams.jsonl (one JSON object per line). On a start or resume it prepares the
    directory (`prepare_run_dir`) and drops the records of teams.jsonl past the checkpoint the
    run continues from (`trim_teams`): those generations are computed again."""

    def __init__(self, run_dir: Path):
        self.run_dir = Path(run_dir)
        self.path = self.run_dir / SUMMARY_FILE
        self.teams = self.run_dir / TEAMS_FILE
        self.parent: dict | None = None
        self.last: dict | None = None

    def on_start(self, ev: Evolution) -> None:
        from .runconfig import read_parent

        prepare_run_dir(self.run_dir)  # no leftover temporary files, no cut-off line
        trim_teams(self.run_dir, ev.state.generation)
        self.parent = read_parent(self.run_dir)

    def _write(self) -> None:
        atomic_write_bytes(self.path, json.dumps(self.last, indent=2).encode())

    def on_generation(self, ev: Evolution, result: GenerationResult) -> None:
        append_line(self.teams, json.dumps(records.team_line(result)))
        self.last = records.summary(ev, result)
        if self.parent is not None:  # a run branched from another (`evolve --from`)
            self.last["parent"] = self.parent
        if ev.done:
            self.last["stop"] = {"reason": "generations", "generation": ev.state.generation}
        self._write()

    def on_stop(self, ev: Evolution, record: dict) -> None:
        """A bound stopped the run (`session.Bounds`): summary.json says which ("stop")."""
        if self.last is not None:
            self.last["stop"] = records.json_clean(record)
            self._write()

    def on_end(self, ev: Evolution) -> None:
        pass


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _tier(v: Any) -> bool:
    """A hardware tier: the integer 1, 2 or 3 (a tensor or a float is not one: `v in (1, 2, 3)`
    alone would compare a tensor elementwise)."""
    return isinstance(v, int) and not isinstance(v, bool) and v in (1, 2, 3)


#: The most robots the designs of a summary.json or teams.jsonl record may add up to (the
#: swarm_size bound); a replay also checks the memory its team needs (`analysis.replay_run`).
MAX_TEAM = 10_000_000


def check_designs(designs: Any, source: str) -> list[dict]:
    """The "designs" of a summary.json or teams.jsonl record, every field checked (RunError
    naming `source`, the design and the field)."""
    if not isinstance(designs, list) or not designs:
        raise RunError(f"{source}: designs: expected a non-empty list, got {short(designs)}")
    for i, d in enumerate(designs):
        w = f"{source}: designs[{i}]"
        if not isinstance(d, dict):
            raise RunError(f"{w}: expected a table, got {short(d)}")
        for key, ok, what in (
            (
                "count",
                lambda v: isinstance(v, int) and not isinstance(v, bool) and v >= 0,
                "an integer >= 0",
            ),
            (
                "species",
                lambda v: isinstance(v, int) and not isinstance(v, bool) and 0 <= v < 2**63,
                "an integer in [0, 2**63)",
            ),
            (
                "effector",
                lambda v: isinstance(v, str) and v in ("suction", "pincher"),
                "suction or pincher",
            ),
            ("radius", lambda v: finite(v) and 0 < v <= 10, "a radius in (0, 10] m"),
            ("chassis_tier", _tier, "1, 2 or 3"),
            ("battery_tier", _tier, "1, 2 or 3"),
            ("motor_tier", _tier, "1, 2 or 3"),
            ("torque_point", lambda v: finite(v), "a finite number"),
            ("battery_point", lambda v: finite(v), "a finite number"),
            ("dominance", lambda v: finite(v), "a finite number"),
            ("cost", lambda v: finite(v), "a finite number"),
            (
                "bt",
                lambda v: (
                    isinstance(v, list)
                    and 0 < len(v) <= 4096
                    and all(
                        isinstance(x, int) and not isinstance(x, bool) and 0 <= x < NUM_OPCODES
                        for x in v
                    )
                ),
                f"a list of opcodes 0..{NUM_OPCODES - 1}",
            ),
        ):
            if key not in d:
                raise RunError(f"{w}: missing {key!r}")
            if not ok(d[key]):
                raise RunError(f"{w}.{key}: expected {what}, got {short(d[key])}")
        # optional: a design recorded before it was written is read with a default
        v = d.get("selectivity", 0.5)
        if not (finite(v)):
            raise RunError(f"{w}.selectivity: expected a finite number, got {short(v)}")
        if "capability" in d and not _capability_ok(d["capability"]):
            raise RunError(
                f"{w}.capability: expected a list of package class indices (distinct, "
                f"ascending, 0..{MAX_PACKAGES - 1}), got {short(d['capability'])}"
            )
    total = sum(d["count"] for d in designs)
    if total < 1:
        raise RunError(f"{source}: designs: the counts add up to no robot")
    if total > MAX_TEAM:
        raise RunError(
            f"{source}: designs: the counts add up to {short(total)} robots, more than any "
            f"run can have ({MAX_TEAM})"
        )
    return designs


def _capability_ok(v: Any) -> bool:
    """A design's recorded capability: the indices of the package classes it lifts, ascending
    and distinct (at most one per class: a scenario has at most MAX_PACKAGES classes)."""
    return (
        isinstance(v, list)
        and len(v) <= MAX_PACKAGES
        and all(isinstance(x, int) and not isinstance(x, bool) for x in v)
        and all(a < b for a, b in zip(v, v[1:]))
        and (not v or (v[0] >= 0 and v[-1] < MAX_PACKAGES))
    )


def short(v: Any) -> str:
    """A value as a message shows it: its repr, cut to 60 characters (a list of 10^6 entries is
    not printed whole first; an integer of more digits than Python converts to text, alone or
    inside, is described)."""
    if isinstance(v, (list, dict)) and len(v) > 20:
        return f"a {'list' if isinstance(v, list) else 'table'} of {len(v)} entries"
    try:
        return f"{v!r:.60}"
    except ValueError:  # sys.get_int_max_str_digits
        return "an integer of more than 4300 digits"


def finite(v: Any) -> bool:
    """A finite number (an integer too large for a float is not one)."""
    try:
        return _is_number(v) and math.isfinite(v)
    except OverflowError:
        return False


def check_capability_classes(designs: list[dict], classes: int, source: str) -> None:
    """RunError naming `source` and the design when a recorded capability (`check_designs`
    checked its form) names a package class the scenario, of `classes` classes, does not
    have."""
    for i, d in enumerate(designs):
        bad = [c for c in d.get("capability", ()) if c >= classes]
        if bad:
            raise RunError(
                f"{source}: designs[{i}].capability: package class {bad[0]} does not exist "
                f"(the run's scenario has {classes}: 0..{classes - 1})"
            )


#: The figures of a run's best team in summary.json (a sweep's table has a column of each).
TEAM_FIGURES = (
    "best_fitness",
    "team_cost",
    "deliveries",
    "deliveries_individual",
    "deliveries_collab",
    "energy_used",
    "num_species",
)
#: summary.json keys that must be numbers (None allowed: a non-finite value).
_SUMMARY_NUMBERS = (*TEAM_FIGURES, "best_generation")


#: What a JSON run file with an integer of more digits than Python converts is told.
_LONG_NUMBER = "an integer of more than 4300 digits (the file is damaged)"


def read_summary(run_dir: Path, figures: bool = True) -> dict:
    """summary.json of a run, checked: a table whose designs are well-formed and (`figures`)
    whose figures are numbers (or null, where a value was not finite) and budget a number or
    null. A replay needs only the designs (figures=False)."""
    path = Path(run_dir) / SUMMARY_FILE
    if not path.is_file():
        raise RunError(
            f"{run_dir} has no {SUMMARY_FILE} (is it a run directory with a finished generation?)"
        )
    text = read_text(path)
    check_nesting(text, str(path))
    try:
        s = json.loads(text)
    except json.JSONDecodeError as e:
        raise RunError(f"{path}: malformed JSON ({e})") from None
    except ValueError:  # an integer too long to convert (sys.get_int_max_str_digits)
        raise RunError(f"{path}: {_LONG_NUMBER}") from None
    except RecursionError:
        raise RunError(f"{path}: nested too deeply") from None
    if not isinstance(s, dict):
        raise RunError(f"{path}: expected a JSON object")
    for key in _SUMMARY_NUMBERS if figures else ():
        if key not in s:
            raise RunError(f"{path}: missing {key!r}")
        v = s[key]
        if v is not None and not (finite(v)):
            raise RunError(f"{path}: {key}: expected a number, got {short(v)}")
    b = s.get("budget")
    if b is not None and not (finite(b)):
        raise RunError(f"{path}: budget: expected a number or null, got {short(b)}")
    if figures:
        _check_reeval_figures(s, path)
    check_designs(s.get("designs"), str(path))
    return s


#: summary.json's figures of the best team's re-evaluation (`best_team.summary_fields`), which
#: a summary written before 0.8 has not: each a number or null.
_REEVAL_NUMBERS = (
    "best_fitness_sd",
    "best_reeval_trials",
    "best_single_trial_fitness",
    "best_single_trial_generation",
)


def _check_reeval_figures(s: dict, path: Path) -> None:
    for key in _REEVAL_NUMBERS:
        v = s.get(key)
        if v is not None and not (finite(v)):
            raise RunError(f"{path}: {key}: expected a number or null, got {short(v)}")
    for key in ("best_fitness_ci95", "best_reeval_seeds"):
        v = s.get(key)
        if v is not None and not (
            isinstance(v, list) and len(v) == 2 and all(finite(x) for x in v)
        ):
            raise RunError(f"{path}: {key}: expected two numbers or null, got {short(v)}")


def read_teams(run_dir: Path) -> dict[int, dict]:
    """generation -> its best-team record, from teams.jsonl (the last record of a generation
    wins after a resume; a line that is not a JSON object, cut short by an interruption, is
    skipped); {} when the run has no teams.jsonl."""
    path = Path(run_dir) / TEAMS_FILE
    out: dict[int, dict] = {}
    if not path.is_file() and not path.is_symlink():
        return out
    for n, line in enumerate(read_text(path, MAX_RECORD_BYTES).splitlines(), 1):
        if nesting_depth(line) > MAX_NESTING:
            raise RunError(
                f"{path}: a record nested {nesting_depth(line)} levels deep (at most {MAX_NESTING})"
            )
        try:
            rec = json.loads(line)
        except json.JSONDecodeError:
            continue  # a line cut short by an interruption
        except ValueError:  # not cut short: an integer too long to convert
            raise RunError(f"{path}: line {n}: {_LONG_NUMBER}") from None
        g = rec.get("generation") if isinstance(rec, dict) else None
        if isinstance(g, int) and not isinstance(g, bool):
            out[g] = rec
    return out


def generation_team(run_dir: Path, generation: int) -> dict:
    """The best team of one generation, from teams.jsonl (`read_teams`); its designs are
    checked (`check_designs`)."""
    path = Path(run_dir) / TEAMS_FILE
    if not path.is_file():
        raise RunError(f"{run_dir} has no {TEAMS_FILE}")
    found = read_teams(run_dir).get(generation)
    if found is None:
        raise RunError(f"{run_dir} has no record of generation {generation}")
    check_designs(found.get("designs"), f"{path} (generation {generation})")
    return found
