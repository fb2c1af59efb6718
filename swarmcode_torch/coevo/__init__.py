"""SwarmCoDe: the config, the population, speciation, partners, evaluation, fitness,
reproduction and the generation. Imports the simulator (`swarmcode_torch.sim`) only."""
