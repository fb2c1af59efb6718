"""The cell-list broad phase gives the same contacts as the dense [E, N, N] solver."""

from dataclasses import replace

import pytest
import torch

from swarmcode_torch.sim.contacts import cell_overflow, collide, neighbour_candidates
from swarmcode_torch.sim.hardware import R_MAX, R_MIN
from swarmcode_torch.sim.state import WorldParams


def crowd(E=3, N=300, arena=12.0, seed=0):
    """Robots packed densely enough that most have several contacts; some slots absent."""
    g = torch.Generator().manual_seed(seed)
    pos = torch.rand(E, N, 2, generator=g) * arena
    vel = (torch.rand(E, N, 2, generator=g) - 0.5) * 1.2
    radius = R_MIN + (R_MAX - R_MIN) * torch.rand(E, N, generator=g)
    mass = 2.0 + 10.0 * torch.rand(E, N, generator=g)
    present = torch.rand(E, N, generator=g) > 0.1
    return pos, vel, radius, mass, present


NO_OBSTACLES = (torch.zeros(3, 0, 2), torch.zeros(3, 0), torch.zeros(3, 0, dtype=torch.bool))


def test_candidates_hold_every_touching_pair_exactly_once():
    pos, _, radius, _, present = crowd()
    params = WorldParams(arena=12.0)
    rows, valid = neighbour_candidates(pos, present, params)
    E, N = present.shape
    listed = torch.zeros(E, N, N + 1, dtype=torch.long)
    listed.scatter_add_(2, torch.where(valid, rows, N), torch.ones_like(rows))
    listed = listed[..., :N]
    assert listed.max() <= 1  # no partner listed twice
    d = (pos[:, :, None] - pos[:, None]).norm(dim=-1)
    touching = (d < radius[:, :, None] + radius[:, None]) & present[:, :, None] & present[:, None]
    touching &= ~torch.eye(N, dtype=torch.bool)
    assert touching.sum() > 1000  # the test is crowded enough
    assert torch.all(listed.bool() | ~touching)  # every contact is a candidate
    assert torch.equal(listed, listed.transpose(1, 2))  # lists are symmetric


@pytest.mark.parametrize("seed", [0, 1])
def test_cells_match_dense_solver(seed):
    pos, vel, radius, mass, present = crowd(seed=seed)
    dense = WorldParams(arena=12.0, broad_phase_min_robots=10**9)
    cells = replace(dense, broad_phase_min_robots=1)
    p1, v1 = collide(pos, vel, radius, mass, present, *NO_OBSTACLES, dense)
    p2, v2 = collide(pos, vel, radius, mass, present, *NO_OBSTACLES, cells)
    assert (p1 - pos).abs().max() > 0.05  # contacts really moved robots
    torch.testing.assert_close(p2, p1, atol=1e-4, rtol=0)  # float32 sums in another order
    torch.testing.assert_close(v2, v1, atol=1e-4, rtol=0)


def test_cells_conserve_momentum_of_robot_contacts():
    pos, vel, radius, mass, present = crowd(arena=40.0)  # walls far: few wall contacts
    pos = pos * 0.5 + 10.0  # crowd in the middle
    params = WorldParams(arena=40.0, broad_phase_min_robots=1)
    _, v = collide(pos, vel, radius, mass, present, *NO_OBSTACLES, params)
    m = torch.where(present, mass, 0.0)[..., None]
    torch.testing.assert_close((m * v).sum(1), (m * vel).sum(1), atol=1e-3, rtol=1e-5)
    assert (v - vel).abs().max() > 0.1


def hex_pack(spacing, n_side, origin=(5.0, 5.0)):
    """[1, n_side**2, 2] centres of a hexagonal packing."""
    i, j = torch.meshgrid(torch.arange(n_side), torch.arange(n_side), indexing="ij")
    x = origin[0] + spacing * (i + 0.5 * (j % 2))
    y = origin[1] + spacing * j * (3**0.5 / 2)
    return torch.stack([x.flatten(), y.flatten()], -1)[None].float()


def test_touching_min_size_robots_fit_the_cell_capacity():
    # the densest legal crowd: touching R_MIN discs (a hexagonal packing puts ~20 in a cell)
    pos = hex_pack(2 * R_MIN, 16)
    present = torch.ones(pos.shape[:2], dtype=torch.bool)
    radius = torch.full(pos.shape[:2], R_MIN + 0.01)  # every neighbour touches
    params = WorldParams(arena=12.0)
    assert not cell_overflow(pos, present, params).any()
    rows, valid = neighbour_candidates(pos, present, params)
    N = pos.shape[1]
    seen = (
        torch.zeros(1, N, N + 1, dtype=torch.long)
        .scatter_add_(2, torch.where(valid, rows, N), torch.ones_like(rows))[..., :N]
        .bool()
    )
    d = (pos[:, :, None] - pos[:, None]).norm(dim=-1)
    touching = (d < radius[:, :, None] + radius[:, None]) & ~torch.eye(N, dtype=torch.bool)
    assert touching.sum() > 5 * N and torch.all(seen | ~touching)


def test_cell_overflow_is_reported():
    pos = hex_pack(0.05, 8)  # 64 centres in one cell
    present = torch.ones(pos.shape[:2], dtype=torch.bool)
    params = WorldParams(arena=12.0)
    assert cell_overflow(pos, present, params).tolist() == [True]
    assert cell_overflow(pos, present, replace(params, cell_capacity=64)).tolist() == [False]
