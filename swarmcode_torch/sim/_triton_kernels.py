# mypy: ignore-errors
# (Triton's DSL, and triton ships no type information)
"""The Triton kernels of `sim.triton_tick` (imported only through it, and only where triton is
installed). Whether they run compiled or in Triton's CPU interpreter is decided when this module
is imported (``TRITON_INTERPRET``); `triton_tick._kernels` re-imports it when that changes.

Every kernel follows the float operations of the Python reference (`contacts.py`, `sense.py`)
in the same order per pair; only the order of the sums over partners (and over obstacles) is
another one. Square roots and divisions are the IEEE ones (`sqrt_rn`, `div_rn`), and launches
pass ``enable_fp_fusion=False``, so that a compiled kernel rounds as torch's eager ops do.
"""

from __future__ import annotations

import triton
import triton.language as tl
from triton import knobs
from triton.runtime.interpreter import InterpretedFunction

INTERPRET = bool(knobs.runtime.interpret)


def _lib(f):
    """One of triton.language's own @jit functions (tl.sum, tl.max, tl.min) as these kernels
    call it. Triton makes them interpreted or compiled once, when triton.language is first
    imported; under the interpreter a compiled one cannot be called, so it is wrapped (its body
    calls only builtins, and the interpreter recognises its reductions by identity)."""
    if INTERPRET and not isinstance(f, InterpretedFunction):
        return InterpretedFunction(f.fn)
    if not INTERPRET and isinstance(f, InterpretedFunction):
        raise RuntimeError(
            "triton.language was imported with TRITON_INTERPRET=1: the compiled Triton kernels "
            "need a process where it was imported without it"
        )
    return f


_sum = _lib(tl.sum)
_max = _lib(tl.max)
_min = _lib(tl.min)


@triton.jit
def _pair_sums(
    s,
    bx,
    by,
    ks,
    kx,
    ky,
    xi,
    yi,
    vxi,
    vyi,
    ri,
    inv_mi,
    xj,
    yj,
    vxj,
    vyj,
    rj,
    inv_mj,
    pair,
    VEL: tl.constexpr,
    DIFF: tl.constexpr,
):
    """The row sums (s, bx, by, ks, kx, ky [BI]) plus those over a tile of pairs (i rows [BI], j
    broadcastable to [BI, BJ]) of the contact solver's coefficients c (positions) and, with VEL,
    k (the pass-0 impulses); without VEL, k's sums gain zeros. Not DIFF: sums
    of c, c x_j, c y_j, k, k x_j, k y_j, as `contacts._robot_contacts_dense` (sums over partners
    of c_ij (x_i - x_j) are x_i sum_j c_ij - sum_j c_ij x_j); DIFF: 0, sum_j c_ij (x_i - x_j),
    sum_j c_ij (y_i - y_j), 0 and the same with k, as `contacts._robot_contacts_cells`."""
    dx = xi[:, None] - xj
    dy = yi[:, None] - yj
    d = tl.sqrt_rn(dx * dx + dy * dy)
    inv_d = tl.div_rn(tl.full(d.shape, 1.0, tl.float32), tl.maximum(d, 1e-6))
    inv_sum = inv_mi[:, None] + inv_mj
    w = tl.div_rn(inv_mi[:, None] + tl.full(inv_sum.shape, 0.0, tl.float32), inv_sum)
    overlap = tl.where(pair, tl.maximum(ri[:, None] + rj - d, 0.0), 0.0)
    c = overlap * w * inv_d
    zero = tl.full([xi.shape[0]], 0.0, tl.float32)
    if DIFF:
        s += zero
        bx += _sum(c * dx, 1)
        by += _sum(c * dy, 1)
    else:
        s += _sum(c, 1)
        bx += _sum(c * xj, 1)
        by += _sum(c * yj, 1)
    if VEL:
        vn = ((vxi[:, None] - vxj) * dx + (vyi[:, None] - vyj) * dy) * inv_d
        jimp = tl.where((overlap > 0) & (vn < 0), tl.div_rn(-2.0 * vn, inv_sum), 0.0)
        k = jimp * inv_d
        if DIFF:
            ks += zero
            kx += _sum(k * dx, 1)
            ky += _sum(k * dy, 1)
        else:
            ks += _sum(k, 1)
            kx += _sum(k * xj, 1)
            ky += _sum(k * yj, 1)
    else:
        ks += zero
        kx += zero
        ky += zero
    return s, bx, by, ks, kx, ky


@triton.jit
def _zero_sums(B: tl.constexpr):
    """The six row sums of `_pair_sums` [B], before any pair."""
    z = tl.full([B], 0.0, tl.float32)
    return z, z, z, z, z, z


@triton.jit
def _load_robots(pos_ptr, vel_ptr, radius_ptr, row, m):
    """Position, velocity and radius of the robots at flat rows `row` (masked by m: zeros)."""
    x = tl.load(pos_ptr + row * 2, mask=m, other=0.0)
    y = tl.load(pos_ptr + row * 2 + 1, mask=m, other=0.0)
    vx = tl.load(vel_ptr + row * 2, mask=m, other=0.0)
    vy = tl.load(vel_ptr + row * 2 + 1, mask=m, other=0.0)
    r = tl.load(radius_ptr + row, mask=m, other=0.0)
    return x, y, vx, vy, r


@triton.jit
def _load_partners(vel_ptr, radius_ptr, mass_ptr, present_ptr, rj_, m):
    """Velocity, radius, inverse mass and presence of the partners at flat rows `rj_` (their
    positions are read by each kernel from where it keeps them)."""
    vxj = tl.load(vel_ptr + rj_ * 2, mask=m, other=0.0)
    vyj = tl.load(vel_ptr + rj_ * 2 + 1, mask=m, other=0.0)
    rj = tl.load(radius_ptr + rj_, mask=m, other=0.0)
    inv_mj = _inv_mass(mass_ptr, rj_, m)
    okj = tl.load(present_ptr + rj_, mask=m, other=0) != 0
    return vxj, vyj, rj, inv_mj, okj


@triton.jit
def _inv_mass(mass_ptr, row, m):
    """1 / mass of the robots at flat rows `row` (masked: 1)."""
    mass = tl.load(mass_ptr + row, mask=m, other=1.0)
    return tl.div_rn(tl.full(mass.shape, 1.0, tl.float32), mass)


@triton.jit
def _store_robots(out_pos_ptr, out_vel_ptr, row, x, y, vx, vy, m):
    """Positions and velocities written at flat rows `row` (where m)."""
    tl.store(out_pos_ptr + row * 2, x, mask=m)
    tl.store(out_pos_ptr + row * 2 + 1, y, mask=m)
    tl.store(out_vel_ptr + row * 2, vx, mask=m)
    tl.store(out_vel_ptr + row * 2 + 1, vy, mask=m)


@triton.jit
def _static(x, y, vx, vy, r, o_pos_ptr, o_rad_ptr, o_pres_ptr, e, O, arena, BO: tl.constexpr):
    """`contacts._static_contacts` for robots [B] of environment e: obstacles (every obstacle
    sees the positions and velocities from before any obstacle), then the walls."""
    dpx = tl.full(x.shape, 0.0, tl.float32)
    dpy = tl.full(x.shape, 0.0, tl.float32)
    dvx = tl.full(x.shape, 0.0, tl.float32)
    dvy = tl.full(x.shape, 0.0, tl.float32)
    for o0 in range(0, O, BO):
        o = o0 + tl.arange(0, BO)
        mo = o < O
        ox = tl.load(o_pos_ptr + (e * O + o) * 2, mask=mo, other=0.0)
        oy = tl.load(o_pos_ptr + (e * O + o) * 2 + 1, mask=mo, other=0.0)
        orad = tl.load(o_rad_ptr + e * O + o, mask=mo, other=0.0)
        opres = tl.load(o_pres_ptr + e * O + o, mask=mo, other=0) != 0
        dx = x[:, None] - ox[None, :]
        dy = y[:, None] - oy[None, :]
        d = tl.sqrt_rn(dx * dx + dy * dy)
        dm = tl.maximum(d, 1e-6)
        nx = tl.div_rn(dx, dm)
        ny = tl.div_rn(dy, dm)
        ov = tl.where(opres[None, :], tl.maximum(r[:, None] + orad[None, :] - d, 0.0), 0.0)
        dpx += _sum(nx * ov, 1)
        dpy += _sum(ny * ov, 1)
        vn = vx[:, None] * nx + vy[:, None] * ny
        h = tl.where((ov > 0) & (vn < 0), 2 * vn, 0.0)
        dvx += _sum(nx * h, 1)
        dvy += _sum(ny * h, 1)
    x = x + dpx
    y = y + dpy
    vx = vx - dvx
    vy = vy - dvy
    lo = r
    hi = arena - r
    vx = tl.where(((x < lo) & (vx < 0)) | ((x > hi) & (vx > 0)), -vx, vx)
    vy = tl.where(((y < lo) & (vy < 0)) | ((y > hi) & (vy > 0)), -vy, vy)
    x = tl.minimum(tl.maximum(x, lo), hi)
    y = tl.minimum(tl.maximum(y, lo), hi)
    return x, y, vx, vy


@triton.jit
def collide_dense_kernel(
    pos_ptr,
    vel_ptr,
    radius_ptr,
    mass_ptr,
    present_ptr,
    o_pos_ptr,
    o_rad_ptr,
    o_pres_ptr,
    out_pos_ptr,
    out_vel_ptr,
    N,
    O,
    arena,
    ITERS: tl.constexpr,
    BN: tl.constexpr,
    BJ: tl.constexpr,
    BO: tl.constexpr,
):
    """`contacts.collide` of one environment (program e) with dense robot pairs: all N robots
    in registers, the ITERS Jacobi passes over tiles of BJ partners, then obstacles and walls.
    No [N, N] array is stored: each pass writes the N positions it starts from to `out_pos`
    (which ends up holding the result), and reads its partners' positions from there."""
    e = tl.program_id(0).to(tl.int64)
    i = tl.arange(0, BN)
    mi = i < N
    row = e * N + i
    x, y, vx, vy, r = _load_robots(pos_ptr, vel_ptr, radius_ptr, row, mi)
    inv_m = _inv_mass(mass_ptr, row, mi)
    ok = (tl.load(present_ptr + row, mask=mi, other=0) != 0) & mi
    for it in tl.static_range(ITERS):
        tl.store(out_pos_ptr + row * 2, x, mask=mi)
        tl.store(out_pos_ptr + row * 2 + 1, y, mask=mi)
        tl.debug_barrier()  # the pass's positions are written before any is read
        s, bx, by, ks, kx, ky = _zero_sums(BN)
        for j0 in range(0, N, BJ):
            j = j0 + tl.arange(0, BJ)
            mj = j < N
            rj_ = e * N + j
            xj = tl.load(out_pos_ptr + rj_ * 2, mask=mj, other=0.0, cache_modifier=".cg")
            yj = tl.load(out_pos_ptr + rj_ * 2 + 1, mask=mj, other=0.0, cache_modifier=".cg")
            vxj, vyj, rj, inv_mj, okj = _load_partners(
                vel_ptr, radius_ptr, mass_ptr, present_ptr, rj_, mj
            )
            pair = ok[:, None] & (okj & mj)[None, :] & (i[:, None] != j[None, :])
            s, bx, by, ks, kx, ky = _pair_sums(
                s, bx, by, ks, kx, ky,  # the row sums so far
                x, y, vx, vy, r, inv_m,  # the robots
                xj[None, :], yj[None, :], vxj[None, :],  # their partners
                vyj[None, :], rj[None, :], inv_mj[None, :],
                pair, it == 0, False,
            )  # fmt: skip
        tl.debug_barrier()  # every partner read before the next pass overwrites out_pos
        nx = x + x * s - bx
        ny = y + y * s - by
        if it == 0:
            vx = vx + inv_m * (x * ks - kx)
            vy = vy + inv_m * (y * ks - ky)
        x = nx
        y = ny
    x, y, vx, vy = _static(x, y, vx, vy, r, o_pos_ptr, o_rad_ptr, o_pres_ptr, e, O, arena, BO)
    _store_robots(out_pos_ptr, out_vel_ptr, row, x, y, vx, vy, mi)


# long: a fused kernel is one function by design (one launch a pass; what two kernels
# share is in the @triton.jit helpers above).
@triton.jit
def collide_cells_kernel(
    pos_ptr,
    vel_ptr,
    radius_ptr,
    mass_ptr,
    present_ptr,
    cell_ptr,
    order_ptr,
    start_ptr,
    o_pos_ptr,
    o_rad_ptr,
    o_pres_ptr,
    out_pos_ptr,
    out_vel_ptr,
    N,
    O,
    G,
    arena,
    PAIRS: tl.constexpr,
    VEL: tl.constexpr,
    STATIC: tl.constexpr,
    BI: tl.constexpr,
    BK: tl.constexpr,
    BO: tl.constexpr,
):
    """One Jacobi pass of the robot contact solver (the form of `contacts._robot_contacts_cells`,
    the reference's broad phase: sums of c_ij (x_i - x_j)) over a cell list (`cell_list.CellList` of
    `pos`), for the BI robots at sorted slots [b BI, (b + 1) BI) of environment e (program
    (e, b)): every robot of the 9 neighbouring cells, BK at a time, up to the fullest of those
    cells (no capacity). VEL: the pass-0 velocity impulses; STATIC: then obstacles and walls.
    Reads `pos`, writes `out_pos` / `out_vel` (other buffers: passes are separate launches)."""
    e = tl.program_id(0).to(tl.int64)
    b = tl.program_id(1)
    slot = b * BI + tl.arange(0, BI)
    ms = slot < N
    i = tl.load(order_ptr + e * N + slot, mask=ms, other=0)
    row = e * N + i
    x, y, vx, vy, r = _load_robots(pos_ptr, vel_ptr, radius_ptr, row, ms)
    if PAIRS:
        inv_m = _inv_mass(mass_ptr, row, ms)
        ok = (tl.load(present_ptr + row, mask=ms, other=0) != 0) & ms
        cell = tl.load(cell_ptr + row, mask=ms, other=0)
        cx = cell // G
        cy = cell % G
        sbase = e * (G * G + 2)
        s, bx, by, ks, kx, ky = _zero_sums(BI)
        for a in range(9):  # the 3 x 3 neighbouring cells (a loop: unrolled, 9x the code)
            ncx = cx + (a // 3 - 1)
            ncy = cy + (a % 3 - 1)
            inside = ok & (ncx >= 0) & (ncx < G) & (ncy >= 0) & (ncy < G)
            nc = ncx * G + ncy
            s0 = tl.load(start_ptr + sbase + nc, mask=inside, other=0)
            s1 = tl.load(start_ptr + sbase + nc + 1, mask=inside, other=0)
            kmax = _max(s1 - s0, 0)
            for k0 in range(0, kmax, BK):
                sl = s0[:, None] + k0 + tl.arange(0, BK)[None, :]
                mk = sl < s1[:, None]
                j = tl.load(order_ptr + e * N + sl, mask=mk, other=0)
                rj_ = e * N + j
                xj = tl.load(pos_ptr + rj_ * 2, mask=mk, other=0.0)
                yj = tl.load(pos_ptr + rj_ * 2 + 1, mask=mk, other=0.0)
                vxj, vyj, rj, inv_mj, okj = _load_partners(
                    vel_ptr, radius_ptr, mass_ptr, present_ptr, rj_, mk
                )
                pair = mk & okj & (j != i[:, None])
                s, bx, by, ks, kx, ky = _pair_sums(
                    s, bx, by, ks, kx, ky,  # the row sums so far
                    x, y, vx, vy, r, inv_m,  # the robots
                    xj, yj, vxj, vyj, rj, inv_mj,  # their partners
                    pair, VEL, True,
                )  # fmt: skip
        nx = x + bx  # as contacts._robot_contacts_cells: sums of c_ij (x_i - x_j)
        ny = y + by
        if VEL:
            vx = vx + inv_m * kx
            vy = vy + inv_m * ky
        x = nx
        y = ny
    if STATIC:
        x, y, vx, vy = _static(x, y, vx, vy, r, o_pos_ptr, o_rad_ptr, o_pres_ptr, e, O, arena, BO)
    _store_robots(out_pos_ptr, out_vel_ptr, row, x, y, vx, vy, ms)


@triton.jit
def sense_kernel(
    pos_ptr,
    gpos_ptr,
    avail_ptr,
    free_ptr,
    compat_ptr,
    keys_ptr,
    best_ptr,
    best_d_ptr,
    rand_ptr,
    rand_d_ptr,
    N,
    H,
    INF,
    BI: tl.constexpr,
    BH: tl.constexpr,
):
    """The robot x grip-point phase of `sense.sense` for BI robots of environment e (program
    (e, b)), over the H grip points BH at a time: the nearest valid grip (`best`, `best_d`) and
    the valid grip with the largest key (`rand`, its distance `rand_d`); ties go to the lowest
    grip index, as torch's min / argmax; no valid grip: index 0 and INF."""
    e = tl.program_id(0).to(tl.int64)
    b = tl.program_id(1)
    i = b * BI + tl.arange(0, BI)
    mi = i < N
    row = e * N + i
    x = tl.load(pos_ptr + row * 2, mask=mi, other=0.0)
    y = tl.load(pos_ptr + row * 2 + 1, mask=mi, other=0.0)
    free = (tl.load(free_ptr + row, mask=mi, other=0) != 0) & mi
    best_d = tl.full([BI], float("inf"), tl.float32)
    best = tl.full([BI], 0, tl.int32)
    rkey = tl.full([BI], float("-inf"), tl.float32)
    rnd = tl.full([BI], 0, tl.int32)
    rnd_d = tl.full([BI], INF, tl.float32)
    for h0 in range(0, H, BH):
        h = h0 + tl.arange(0, BH)
        mh = h < H
        gx = tl.load(gpos_ptr + (e * H + h) * 2, mask=mh, other=0.0)
        gy = tl.load(gpos_ptr + (e * H + h) * 2 + 1, mask=mh, other=0.0)
        av = (tl.load(avail_ptr + e * H + h, mask=mh, other=0) != 0) & mh
        m2 = mi[:, None] & mh[None, :]
        nh = row[:, None] * H + h[None, :]
        cp = tl.load(compat_ptr + nh, mask=m2, other=0) != 0
        key = tl.load(keys_ptr + nh, mask=m2, other=0.0)
        dx = gx[None, :] - x[:, None]
        dy = gy[None, :] - y[:, None]
        dist = tl.sqrt_rn(dx * dx + dy * dy)
        valid = cp & av[None, :] & free[:, None]
        dm = tl.where(valid, dist, INF)
        dm = tl.where(mh[None, :], dm, float("inf"))  # past H: never the minimum
        cmin, carg = _min(dm, 1, return_indices=True, return_indices_tie_break_left=True)
        upd = cmin < best_d  # strict: an earlier chunk keeps a tie
        best = tl.where(upd, h0 + carg, best)
        best_d = tl.where(upd, cmin, best_d)
        score = tl.where(valid, key, -1.0)
        score = tl.where(mh[None, :], score, -2.0)  # past H: never the maximum
        cmax, cargm = _max(score, 1, return_indices=True, return_indices_tie_break_left=True)
        updr = cmax > rkey
        at = h[None, :] == (h0 + cargm)[:, None]
        cd = _sum(tl.where(at, tl.where(mh[None, :], dm, 0.0), 0.0), 1)  # dm at the argmax
        rnd = tl.where(updr, h0 + cargm, rnd)
        rkey = tl.where(updr, cmax, rkey)
        rnd_d = tl.where(updr, cd, rnd_d)
    best_d = tl.minimum(best_d, INF)
    tl.store(best_ptr + row, best.to(tl.int64), mask=mi)
    tl.store(best_d_ptr + row, best_d, mask=mi)
    tl.store(rand_ptr + row, rnd.to(tl.int64), mask=mi)
    tl.store(rand_d_ptr + row, rnd_d, mask=mi)
