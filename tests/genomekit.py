"""Random genomes for operator tests."""

import torch

from swarmcode_torch.coevo.population import R_MAX, R_MIN, Population


def random_genomes(n, gen, l_tag=8, l_bt=12):
    """n random genomes (tags of l_tag bits, trees of l_bt random opcodes)."""
    return Population(
        tag=torch.rand(n, l_tag, generator=gen) < 0.5,
        selectivity=torch.rand(n, generator=gen), dominance=torch.rand(n, generator=gen),
        bt=torch.randint(0, 14, (n, l_bt), generator=gen),
        radius=R_MIN + (R_MAX - R_MIN) * torch.rand(n, generator=gen),
        chassis=torch.randint(0, 3, (n,), generator=gen),
        battery=torch.randint(0, 3, (n,), generator=gen),
        motor=torch.randint(0, 3, (n,), generator=gen),
        torque_point=torch.rand(n, generator=gen), battery_point=torch.rand(n, generator=gen),
        effector=torch.randint(0, 2, (n,), generator=gen))
