"""The SwarmCoDe genome (paper Table I), held for a whole population as a batch of tensors."""

from __future__ import annotations

from dataclasses import dataclass, fields

import torch

from ..sim.hardware import NUM_TIERS, PINCHER, R_MAX, R_MIN, SUCTION, Catalog, Phenotype, phenotype


@dataclass
class Population:
    """A population of P genomes; every field has leading dimension P.

    Tiers are stored as indices 0..2 (the paper's tiers 1..3).
    """

    tag: torch.Tensor          # [P, L_tag] bool — speciation / partner tag
    selectivity: torch.Tensor  # [P] float in [0, 1] — max tag distance of a partner
    dominance: torch.Tensor    # [P] float in [0, 1] — relative share of the swarm
    bt: torch.Tensor           # [P, L_bt] long — behavior-tree opcodes (NOP padded)
    radius: torch.Tensor       # [P] float in [R_MIN, R_MAX]
    chassis: torch.Tensor      # [P] long in {0, 1, 2}
    battery: torch.Tensor      # [P] long in {0, 1, 2}
    motor: torch.Tensor        # [P] long in {0, 1, 2}
    torque_point: torch.Tensor   # [P] float in [0, 1] — motor operating point
    battery_point: torch.Tensor  # [P] float in [0, 1] — battery capacity operating point
    effector: torch.Tensor     # [P] long — SUCTION (0) or PINCHER (1)

    @property
    def size(self) -> int:
        return int(self.selectivity.shape[0])

    def index(self, idx: torch.Tensor | slice) -> "Population":
        """Rows `idx` of every field (a new Population)."""
        return Population(**{f.name: getattr(self, f.name)[idx] for f in fields(self)})

    def to(self, device: torch.device | str) -> "Population":
        return Population(**{f.name: getattr(self, f.name).to(device) for f in fields(self)})

    def clone(self) -> "Population":
        return Population(**{f.name: getattr(self, f.name).clone() for f in fields(self)})

    def state_dict(self) -> dict[str, torch.Tensor]:
        return {f.name: getattr(self, f.name).detach().cpu() for f in fields(self)}

    @classmethod
    def from_state_dict(cls, d: dict[str, torch.Tensor]) -> "Population":
        names = [f.name for f in fields(cls)]
        missing = [n for n in names if n not in d]
        if missing:
            raise ValueError(f"genome is missing fields: {', '.join(missing)}")
        return cls(**{n: d[n] for n in names})

    @staticmethod
    def cat(parts: list["Population"]) -> "Population":
        return Population(**{f.name: torch.cat([getattr(p, f.name) for p in parts])
                         for f in fields(Population)})

    def hardware_vector(self, tiers: bool = False) -> torch.Tensor:
        """[P, D] the hardware space of d_hw, each axis in [0, 1]: the two continuous operating
        points (torque, battery; D = 2), the paper's "continuous hardware space"; with `tiers`
        also the three tiers scaled to [0, 1] first (D = 5, the behaviour before the paper-text
        fix). Radius and tool are excluded (they have their own terms)."""
        points = [self.torque_point, self.battery_point]
        if tiers:
            t = float(NUM_TIERS - 1)
            points = [self.chassis / t, self.battery / t, self.motor / t] + points
        return torch.stack(points, dim=-1).float()


def genome_phenotype(genome: "Population", catalog: Catalog | None = None) -> Phenotype:
    """Phenotype of every individual of a population (`Population`)."""
    return phenotype(genome.radius, genome.chassis, genome.battery, genome.motor,
                     genome.torque_point, genome.battery_point, genome.effector, catalog)
