"""One tick of the batched world: sensing -> behavior trees -> drop / pick-up -> PD control
-> physics and contacts -> energy, stuck detection and waypoints.

One call of :func:`step` is one tick for the whole batch: fixed shapes, no Python loop over
robots, packages or environments, and no host synchronisation, so it compiles to few kernels.
"""

from __future__ import annotations

import torch

from . import bt
from .contacts import _gather, collide
from .layout import Layout
from .sense import _INF, Senses, sense
from .state import DELIVERED, GROUND, HELD, Robots, State, WorldParams, _waypoints

_MOVE_ACTIONS = (
    bt.ACT_MOVE_TO_PACK,
    bt.ACT_MOVE_TO_BASE,
    bt.ACT_RANDOM_WALK,
    bt.ACT_MOVE_TO_RANDOM_PACK,
)


def _scatter_sum(values: torch.Tensor, index: torch.Tensor, size: int) -> torch.Tensor:
    """Sum values [E, N, *] into [E, size, *] by index [E, N] (index == size is dropped)."""
    E = index.shape[0]
    shape = (E, size + 1) + tuple(values.shape[2:])
    idx = index.reshape(index.shape + (1,) * (values.dim() - 2)).expand_as(values)
    return values.new_zeros(shape).scatter_add(1, idx, values)[:, :size]


def _cap(v: torch.Tensor, vmax: float, vmin: float = 0.0) -> torch.Tensor:
    """Limit speeds to vmax; speeds below vmin become 0 (static friction)."""
    n = v.norm(dim=-1, keepdim=True)
    return torch.where(n < vmin, 0.0, v * (vmax / n.clamp_min(vmax)))


# ---------------------------------------------------------------- the phases of a tick
def _grips(
    state: State, layout: Layout, s: Senses, fired: torch.Tensor, params: WorldParams
) -> tuple[torch.Tensor, ...]:
    """Drop, then pick up -> holder [E, H], holding, grip, lifted [E, Q], p_status, p_picked."""
    E, N = state.holding.shape
    Q, G = layout.g_effector.shape[1:]
    H = Q * G
    dev = state.pos.device
    holder = state.holder.reshape(E, H)
    holding, grip = state.holding, state.grip
    robot_ids = torch.arange(N, device=dev).expand(E, N)

    # --- drop: release the grip; inside the base the package is delivered
    drop = fired[..., bt.ACT_DROP] & (holding >= 0)
    my_grip = torch.where(holding >= 0, holding * G + grip, H)
    released = _scatter_sum(drop.float(), torch.where(drop, my_grip, H), H) > 0  # [E, H]
    deliver = drop & (s.d_base <= params.base_radius)
    delivered_now = _scatter_sum(deliver.float(), torch.where(deliver, holding, Q), Q) > 0
    delivered = (state.p_status == DELIVERED) | delivered_now  # [E, Q]
    gone = delivered.repeat_interleave(G, dim=1)
    holder = torch.where(released | gone, -1, holder)
    lost = (holding >= 0) & _gather(delivered.long(), holding).bool()
    holding = torch.where(drop | lost, -1, holding)

    # --- pick up: the nearest takeable grip in reach; ties go to the lowest robot index
    pick = fired[..., bt.ACT_PICK_UP] & (holding < 0) & (s.best_d <= params.reach)
    claim = torch.where(pick, s.best, H)
    winner = torch.full((E, H + 1), N, dtype=torch.long, device=dev).scatter_reduce(
        1, claim, robot_ids, reduce="amin"
    )
    got = pick & (winner.gather(1, claim) == robot_ids)
    holder = torch.cat([holder, holder.new_full((E, 1), -1)], 1).scatter(
        1, torch.where(got, s.best, H), robot_ids
    )[:, :H]
    holding = torch.where(got, s.best // G, holding)
    grip = torch.where(got, s.best % G, grip)

    holder3 = holder.reshape(E, Q, G)
    exists = layout.g_effector >= 0
    held_any = (holder3 >= 0).any(-1)
    lifted = ((holder3 >= 0) | ~exists).all(-1) & exists.any(-1) & ~delivered
    p_status = torch.where(delivered, DELIVERED, torch.where(held_any, HELD, GROUND))
    p_picked = state.p_picked | lifted
    return holder, holding, grip, lifted, p_status, p_picked


def _targets(state: State, s: Senses, action: torch.Tensor, params: WorldParams) -> torch.Tensor:
    """Where each robot wants to go [E, N, 2]: its own position unless a move action says."""
    E, N = action.shape
    base = state.pos.new_tensor([params.arena / 2, params.arena / 2])
    target = state.pos
    target = torch.where(
        (action == bt.ACT_MOVE_TO_PACK)[..., None] & (s.best_d < _INF)[..., None],
        _gather(s.gpos, s.best),
        target,
    )
    target = torch.where(
        (action == bt.ACT_MOVE_TO_RANDOM_PACK)[..., None] & (s.rand_d < _INF)[..., None],
        _gather(s.gpos, s.rand),
        target,
    )
    target = torch.where((action == bt.ACT_MOVE_TO_BASE)[..., None], base.expand(E, N, 2), target)
    return torch.where((action == bt.ACT_RANDOM_WALK)[..., None], state.waypoint, target)


def _control(
    state: State,
    layout: Layout,
    robots: Robots,
    alive: torch.Tensor,
    holding: torch.Tensor,
    target: torch.Tensor,
    params: WorldParams,
) -> tuple[torch.Tensor, torch.Tensor]:
    """PD control (cascaded: position error -> desired velocity -> force), force-limited ->
    f_cmd [E, N, 2] and each robot's share of the mass it carries [E, N]."""
    carrying = holding >= 0
    n_grips = (layout.g_effector >= 0).sum(-1).clamp_min(1)
    share = torch.where(carrying, _gather(layout.p_mass / n_grips, holding), 0.0)
    m_ctrl = robots.mass + share
    v_des = _cap(params.kp * (target - state.pos), params.v_cap)
    f_cmd = m_ctrl[..., None] * (params.kv * (v_des - state.vel) + params.drag * v_des)
    f_max = torch.where(alive, robots.force, 0.0)[..., None]
    f_cmd = f_cmd * (f_max / f_cmd.norm(dim=-1, keepdim=True).clamp_min(1e-9)).clamp(max=1.0)
    return f_cmd, share


def _move(
    state: State,
    layout: Layout,
    robots: Robots,
    f_cmd: torch.Tensor,
    holding: torch.Tensor,
    grip: torch.Tensor,
    lifted: torch.Tensor,
    params: WorldParams,
) -> tuple[torch.Tensor, ...]:
    """Free robots by semi-implicit Euler; lifted packages as one rigid body with their
    carriers -> pos, vel, p_pos, p_vel, pidx (the package each robot moves with, Q: none),
    in_lifted, g_off (each robot's grip offset)."""
    E = holding.shape[0]
    Q, G = layout.g_effector.shape[1:]
    H = Q * G
    carrying = holding >= 0
    vel = _cap(
        state.vel + params.dt * (f_cmd / robots.mass[..., None] - params.drag * state.vel),
        params.v_cap,
        params.rest_speed,
    )
    pos = state.pos + params.dt * vel

    in_lifted = carrying & _gather(lifted.long(), holding).bool()
    pidx = torch.where(in_lifted, holding, Q)
    f_pkg = _scatter_sum(f_cmd, pidx, Q)
    m_pkg = layout.p_mass + _scatter_sum(robots.mass, pidx, Q)
    p_vel = torch.where(
        lifted[..., None],
        _cap(
            state.p_vel + params.dt * (f_pkg / m_pkg[..., None] - params.drag * state.p_vel),
            params.v_cap,
            params.rest_speed,
        ),
        0.0,
    )
    p_pos = state.p_pos + params.dt * p_vel
    g_off = _gather(layout.g_offset.reshape(E, H, 2), holding * G + grip)
    pos = torch.where(carrying[..., None], _gather(p_pos, holding) + g_off, pos)
    vel = torch.where(carrying[..., None], _gather(p_vel, holding), vel)
    return pos, vel, p_pos, p_vel, pidx, in_lifted, g_off


def _stuck_and_waypoints(
    state: State,
    action: torch.Tensor,
    alive: torch.Tensor,
    target: torch.Tensor,
    pos: torch.Tensor,
    params: WorldParams,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Stuck detection and random-walk waypoints -> stuck, t, waypoint."""
    moving = torch.zeros_like(alive)
    for a in _MOVE_ACTIONS:
        moving = moving | (action == a)
    trying = moving & ((target - state.pos).norm(dim=-1) > params.reach)
    slow = (pos - state.pos).norm(dim=-1) < params.stuck_speed * params.dt
    stuck = torch.where(trying & slow, state.stuck + 1, 0)
    t = state.t + 1
    redraw = ((state.waypoint - pos).norm(dim=-1) <= params.reach) | (
        t % params.waypoint_period == 0
    )
    waypoint = torch.where(redraw[..., None], _waypoints(state.wp_key, t, params), state.waypoint)
    return stuck, t, waypoint


# ---------------------------------------------------------------- one tick
def step(
    state: State,
    layout: Layout,
    robots: Robots,
    compat: torch.Tensor,
    keys: torch.Tensor,
    tables: torch.Tensor,
    params: WorldParams,
) -> State:
    """Advance every environment by one tick. `sense` and `collide` are called here, not in a
    phase function: `triton_tick.step_triton` is this function's code with those two names
    bound to its kernels."""
    E = robots.radius.shape[0]
    Q, G = layout.g_effector.shape[1:]
    s = sense(state, layout, robots, compat, keys, params)

    # --- the behavior trees
    alive = robots.present & (state.energy > 0)
    action, fired, _ = bt.lookup(tables, robots.program, s.leaf)
    action = torch.where(alive, action, bt.NOP)
    fired = fired & alive[..., None]

    holder, holding, grip, lifted, p_status, p_picked = _grips(state, layout, s, fired, params)
    target = _targets(state, s, action, params)
    f_cmd, share = _control(state, layout, robots, alive, holding, target, params)
    pos, vel, p_pos, p_vel, pidx, in_lifted, g_off = _move(
        state, layout, robots, f_cmd, holding, grip, lifted, params
    )

    # --- contacts; carriers pass their correction on to the package they hold
    carrying = holding >= 0
    waiting = carrying & ~in_lifted
    m_col = torch.where(waiting, params.anchor_mass, robots.mass + share)
    pos_c, vel_c = collide(
        pos,
        vel,
        robots.radius,
        m_col,
        robots.present,
        layout.o_pos,
        layout.o_radius,
        layout.o_present,
        params,
    )
    cnt = _scatter_sum(torch.ones_like(robots.mass), pidx, Q).clamp_min(1)[..., None]
    p_pos = p_pos + torch.where(lifted[..., None], _scatter_sum(pos_c - pos, pidx, Q) / cnt, 0.0)
    p_vel = torch.where(lifted[..., None], _scatter_sum(vel_c, pidx, Q) / cnt, p_vel)
    pos = torch.where(carrying[..., None], _gather(p_pos, holding) + g_off, pos_c)
    vel = torch.where(carrying[..., None], _gather(p_vel, holding), vel_c)

    # --- energy: mechanical power through the motor efficiency, plus idle draw
    p_mech = (f_cmd * vel).sum(-1).clamp_min(0)
    used = params.dt * (p_mech / robots.efficiency + params.idle_power)
    energy = torch.where(robots.present, (state.energy - used).clamp_min(0), 0.0)

    stuck, t, waypoint = _stuck_and_waypoints(state, action, alive, target, pos, params)

    # contiguous, like reset()'s holder: a strided view here would make a compiled step (which
    # guards on input strides) compile a second time on its second call
    return State(
        t,
        pos,
        vel,
        energy,
        holding,
        grip,
        stuck,
        waypoint,
        p_pos,
        p_vel,
        p_status,
        holder.reshape(E, Q, G).contiguous(),
        p_picked,
        state.wp_key,
    )
