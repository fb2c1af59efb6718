"""The SwarmCoDe genome (paper Table I), held for a whole population as a batch of tensors."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import Any

import torch

from ..sim.bt import NOP, NUM_OPCODES
from ..sim.hardware import NUM_TIERS, PINCHER, R_MAX, R_MIN, SUCTION, Catalog, Phenotype, phenotype
from ..sim.tensors import cast

#: Closed interval of every continuous gene: drawn uniformly in it, mutated within it.
GENE_BOUNDS: dict[str, tuple[float, float]] = {
    "selectivity": (0.0, 1.0),
    "dominance": (0.0, 1.0),
    "radius": (R_MIN, R_MAX),
    "torque_point": (0.0, 1.0),
    "battery_point": (0.0, 1.0),
}
#: Number of values (0..n-1) of every categorical gene: the part tiers (the paper's tiers
#: 1..NUM_TIERS) and the effector (SUCTION, PINCHER).
GENE_VALUES: dict[str, int] = {
    "chassis": NUM_TIERS,
    "battery": NUM_TIERS,
    "motor": NUM_TIERS,
    "effector": 2,
}
#: The social genes (mutated with social_sigma; the other continuous genes with hw_sigma).
SOCIAL_GENES: tuple[str, ...] = ("selectivity", "dominance")
#: The hardware genes: every continuous or categorical gene but the social ones (what a design
#: is built of; `refound.random_hardware` draws them afresh).
HARDWARE_GENES: tuple[str, ...] = tuple(
    n for n in (*GENE_BOUNDS, *GENE_VALUES) if n not in SOCIAL_GENES
)
#: Gene groups inherited together in uniform crossover (tier + operating point of one part move
#: together).
CROSSOVER_GROUPS: tuple[tuple[str, ...], ...] = (
    ("selectivity",),
    ("dominance",),
    ("radius",),
    ("chassis",),
    ("battery", "battery_point"),
    ("motor", "torque_point"),
    ("effector",),
)
EFFECTOR_CODES: dict[str, int] = {"suction": SUCTION, "pincher": PINCHER}


@dataclass
class Population:
    """A population of P genomes; every field has leading dimension P.

    Tiers are stored as indices 0..2 (the paper's tiers 1..3).
    """

    tag: torch.Tensor  # [P, L_tag] bool — speciation / partner tag
    selectivity: torch.Tensor  # [P] float in [0, 1] — max tag distance of a partner
    dominance: torch.Tensor  # [P] float in [0, 1] — relative share of the swarm
    bt: torch.Tensor  # [P, L_bt] long — behavior-tree opcodes (NOP padded)
    radius: torch.Tensor  # [P] float in [R_MIN, R_MAX]
    chassis: torch.Tensor  # [P] long in {0, 1, 2}
    battery: torch.Tensor  # [P] long in {0, 1, 2}
    motor: torch.Tensor  # [P] long in {0, 1, 2}
    torque_point: torch.Tensor  # [P] float in [0, 1] — motor operating point
    battery_point: torch.Tensor  # [P] float in [0, 1] — battery capacity operating point
    effector: torch.Tensor  # [P] long — SUCTION (0) or PINCHER (1)

    @classmethod
    def random(
        cls,
        n: int,
        tag_length: int,
        bt: torch.Tensor | int,
        generator: torch.Generator,
        device: torch.device | str = "cpu",
    ) -> Population:
        """n random genomes, drawn field by field in field order: tag bits w.p. 1/2, continuous
        genes uniform in GENE_BOUNDS, categorical ones uniform in 0..GENE_VALUES - 1; `bt` the
        [n, L] programs, or a length L for uniformly random opcodes."""
        out = {}
        for name in (f.name for f in fields(cls)):
            if name == "tag":
                out[name] = torch.rand(n, tag_length, generator=generator, device=device) < 0.5
            elif name == "bt":
                out[name] = (
                    bt
                    if isinstance(bt, torch.Tensor)
                    else torch.randint(0, NUM_OPCODES, (n, bt), generator=generator, device=device)
                )
            elif name in GENE_BOUNDS:
                lo, hi = GENE_BOUNDS[name]
                out[name] = lo + (hi - lo) * torch.rand(n, generator=generator, device=device)
            else:
                out[name] = torch.randint(
                    0, GENE_VALUES[name], (n,), generator=generator, device=device
                )
        return cls(**out)

    @property
    def size(self) -> int:
        return int(self.selectivity.shape[0])

    def index(self, idx: torch.Tensor | slice) -> Population:
        """Rows `idx` of every field (a new Population)."""
        return Population(**{f.name: getattr(self, f.name)[idx] for f in fields(self)})

    def to(self, device: torch.device | str) -> Population:
        return Population(
            **{f.name: cast(getattr(self, f.name), device=device) for f in fields(self)}
        )

    def clone(self) -> Population:
        return Population(**{f.name: getattr(self, f.name).clone() for f in fields(self)})

    def state_dict(self) -> dict[str, torch.Tensor]:
        return {f.name: getattr(self, f.name).detach().cpu() for f in fields(self)}

    @classmethod
    def from_state_dict(cls, d: dict[str, torch.Tensor]) -> Population:
        names = [f.name for f in fields(cls)]
        missing = [n for n in names if n not in d]
        if missing:
            raise ValueError(f"genome is missing fields: {', '.join(missing)}")
        return cls(**{n: d[n] for n in names})

    def where(self, mask: torch.Tensor, other: Population) -> Population:
        """[N] bool, `other` [N] -> Population [N]: this population's rows where mask, else
        other's."""
        out = {}
        for f in fields(self):
            x, y = getattr(self, f.name), getattr(other, f.name)
            out[f.name] = torch.where(mask.view(-1, *([1] * (x.dim() - 1))), x, y)
        return Population(**out)

    @staticmethod
    def cat(parts: list[Population]) -> Population:
        return Population(
            **{f.name: torch.cat([getattr(p, f.name) for p in parts]) for f in fields(Population)}
        )

    def hardware_vector(self) -> torch.Tensor:
        """[P, 2] the hardware space of d_hw, each axis in [0, 1]: the two continuous operating
        points (torque, battery), the paper's "continuous hardware space". Radius and tool are
        excluded (they have their own terms)."""
        return cast(torch.stack([self.torque_point, self.battery_point], dim=-1), torch.float)


def genome_phenotype(genome: Population, catalog: Catalog | None = None) -> Phenotype:
    """Phenotype of every individual of a population (`Population`)."""
    return phenotype(
        genome.radius,
        genome.chassis,
        genome.battery,
        genome.motor,
        genome.torque_point,
        genome.battery_point,
        genome.effector,
        catalog,
    )


def design_record(genome: Population, row: int, species: int, cost: float) -> dict:
    """A JSON-friendly description of one robot design (row `row`; tiers 1..NUM_TIERS)."""
    return {
        "species": species,
        "effector": "pincher" if int(genome.effector[row]) else "suction",
        "radius": round(float(genome.radius[row]), 4),
        "chassis_tier": int(genome.chassis[row]) + 1,
        "battery_tier": int(genome.battery[row]) + 1,
        "motor_tier": int(genome.motor[row]) + 1,
        "torque_point": round(float(genome.torque_point[row]), 4),
        "battery_point": round(float(genome.battery_point[row]), 4),
        "dominance": round(float(genome.dominance[row]), 4),
        "selectivity": round(float(genome.selectivity[row]), 4),
        "cost": round(cost, 2),
        "bt": [int(x) for x in genome.bt[row].tolist()],
    }


def from_designs(designs: Sequence[dict], tag_length: int = 16) -> tuple[Population, torch.Tensor]:
    """`design_record` dicts -> (a Population with one row per design, [D] long robots per design).

    Tiers 1..3, effector by name or code, "bt" opcode list (NOP padded to the longest), "count"
    robots each (default 1), dominance and selectivity 0.5 when missing; tags all zero.
    ValueError for a missing field, an unknown effector, a tier or opcode out of range, a
    negative count, no design or counts adding up to no robot.
    """
    if not designs:
        raise ValueError("no designs: a team needs at least one robot design")
    rows: list[dict[str, Any]] = []
    for i, d in enumerate(designs):
        try:
            eff = d["effector"]
            if isinstance(eff, str):
                if eff not in EFFECTOR_CODES:
                    raise ValueError(f"design {i}: unknown effector {eff!r} (suction or pincher)")
                eff = EFFECTOR_CODES[eff]
            tiers = [int(d[k]) - 1 for k in ("chassis_tier", "battery_tier", "motor_tier")]
            if not all(0 <= t <= 2 for t in tiers):
                raise ValueError(f"design {i}: tiers must be 1..3, got {[t + 1 for t in tiers]}")
            count = int(d.get("count", 1))
            if count < 0:
                raise ValueError(f"design {i}: count must be >= 0, got {count}")
            rows.append(
                dict(
                    radius=float(d["radius"]),
                    chassis=tiers[0],
                    battery=tiers[1],
                    motor=tiers[2],
                    torque_point=float(d["torque_point"]),
                    battery_point=float(d["battery_point"]),
                    effector=int(eff),
                    dominance=float(d.get("dominance", 0.5)),
                    selectivity=float(d.get("selectivity", 0.5)),
                    bt=[int(x) for x in d["bt"]],
                    count=count,
                )
            )
        except KeyError as e:
            raise ValueError(f"design {i}: missing field {e.args[0]!r}") from None
    length = max(max(len(r["bt"]) for r in rows), 1)
    programs = torch.tensor(
        [r["bt"] + [NOP] * (length - len(r["bt"])) for r in rows], dtype=torch.long
    )
    if ((programs < 0) | (programs >= NUM_OPCODES)).any():
        raise ValueError(f"design bt lists must hold opcodes 0..{NUM_OPCODES - 1}")

    def floats(k: str) -> torch.Tensor:
        return torch.tensor([r[k] for r in rows], dtype=torch.float)

    def longs(k: str) -> torch.Tensor:
        return torch.tensor([r[k] for r in rows], dtype=torch.long)

    genome = Population(
        tag=torch.zeros(len(rows), tag_length, dtype=torch.bool),
        selectivity=floats("selectivity"),
        dominance=floats("dominance"),
        bt=programs,
        radius=floats("radius"),
        chassis=longs("chassis"),
        battery=longs("battery"),
        motor=longs("motor"),
        torque_point=floats("torque_point"),
        battery_point=floats("battery_point"),
        effector=longs("effector"),
    )
    counts = longs("count")
    if int(counts.sum()) == 0:
        raise ValueError("the designs' counts add up to no robot")
    return genome, counts
