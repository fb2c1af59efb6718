"""Random genomes for operator tests."""

from swarmcode_torch.coevo.population import Population


def random_genomes(n, gen, l_tag=8, l_bt=12):
    """n random genomes (tags of l_tag bits, trees of l_bt random opcodes)."""
    return Population.random(n, l_tag, l_bt, gen)
