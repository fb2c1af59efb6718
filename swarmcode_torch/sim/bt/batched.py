"""The batched evaluation of programs, two ways: the masked interpreter (`compute_jumps`,
`interpret`: fixed-step, no data-dependent Python control flow and no host syncs, so
torch.compile and CUDA-graph friendly) and the fast path (`build_tables`: every program's packed
outcome for all NUM_COMBOS leaf-status combinations, once per generation; `lookup`: then one
gather per robot per tick)."""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import torch
import torch.nn.functional as F

from ..tensors import cast
from .ops import (
    _CODE_SHIFT,
    _FIRED_SHIFT,
    _STATUS_SHIFT,
    ACT_MOVE_TO_PACK,
    ACTION_OPS,
    COND_HAS_PACKAGE,
    CONDITION_OPS,
    END,
    FAILURE,
    NOP,
    NUM_COMBOS,
    NUM_OPCODES,
    RUNNING,
    SEL,
    SEQ,
    SUCCESS,
    _default,
    _gather1,
    _is_action,
    _is_leaf,
    _set1,
)


class _Slots(NamedTuple):
    """Slot numbers and node numbers of a program length L for `_nesting` and `_continuations`
    (built once per L and device, never written to)."""

    slot: torch.Tensor  # [L] 0..L-1
    next_slot: torch.Tensor  # [L] 1..L
    next_col: torch.Tensor  # [L, 1] 1..L
    arrival_key: torch.Tensor  # [L + 1] 2 * slot: an arrival's place among equal depths
    opener_key: torch.Tensor  # [L] 2 * slot + 1: an opener's, just after the arrival at it
    s: torch.Tensor  # [2] the two statuses a child returns (SUCCESS, FAILURE)
    leaf_node: torch.Tensor  # [L] the code "visit leaf slot i"
    end_node: torch.Tensor  # [L] T(i, SUCCESS) of an END at slot i
    codes: torch.Tensor  # [L + 2] the code nodes
    root_codes: torch.Tensor  # [2] the codes "the tick ends with root status s"


def _slots(L: int, device: torch.device) -> _Slots:
    """`_Slots` of length L: cached, but built afresh while torch.compile traces (it would
    bypass the cache and warn)."""
    if torch.compiler.is_compiling():
        return _build_slots(L, device)
    return _cached_slots(L, device)


def _build_slots(L: int, device: torch.device) -> _Slots:
    slot = torch.arange(L + 2, device=device)
    n_t, n_c = L + 1, 3 * L + 1  # `_continuations`' first T node and first code node
    return _Slots(
        slot=slot[:L],
        next_slot=slot[1 : L + 1],
        next_col=slot[1 : L + 1, None],
        arrival_key=2 * slot[: L + 1],
        opener_key=2 * slot[:L] + 1,
        s=slot[:2],
        leaf_node=n_c + slot[:L],
        end_node=n_t + 2 * slot[:L],
        codes=n_c + slot,
        root_codes=n_c + L + slot[:2],
    )


_cached_slots = functools.lru_cache(maxsize=32)(_build_slots)


def _nesting(ops: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """ops [B, L] long -> (close [B, L] bool: an END that closes a block; encl [B, L + 1] long:
    the opener slot of the innermost block open on arriving at slot i (i = L: the array's end),
    -1 at top level; end [B, L] long: at an opener, the slot of its matching END, L if unclosed).

    A fixed number of batched ops, no loop over slots: the depth is the walk of +1 (SEQ / SEL)
    and -1 (END) clamped at 0 (the prefix sum less its running minimum below 0, so an END with
    no open block is ignored); the block open at slot i is the last opener before i whose depth
    after it is the depth on arriving at i (found by one sort and a running maximum), and a
    block's END is the closing END whose innermost open block it is."""
    B, L = ops.shape
    k = _slots(L, ops.device)
    push = ops <= SEL
    is_end = ops == END
    s = push.long().masked_fill(is_end, -1).cumsum(1)  # +1 at an opener, -1 at an END
    after = s - torch.cummin(s, 1).values.clamp(max=0)  # depth after each slot
    before = F.pad(after, (1, 0))  # [B, L + 1] depth on arriving at each slot
    close = is_end & (before[:, :L] > 0)
    # openers and the arrivals at every slot in one order, by (depth, slot): an opener at o sorts
    # after the arrival at o and before the arrival at o + 1; the running maximum of the openers'
    # (depth, slot + 1) read at an arrival is the last opener before it at the largest depth up
    # to its own: its innermost open block where that depth is its own
    span = 2 * L + 2
    q_key = before * span + k.arrival_key
    o_key = torch.where(push, after * span + k.opener_key, (L + 1) * span)
    o_val = torch.where(push, after * (L + 1) + k.next_slot, 0)
    keys = torch.cat([q_key, o_key], 1)
    vals = F.pad(o_val, (L + 1, 0))  # the arrivals' values: 0
    order = keys.argsort(1)
    run = torch.cummax(vals.gather(1, order), 1).values
    seen = run.scatter(1, order, run)[:, : L + 1]  # `order` is a permutation: all written
    # the slot of that opener where its depth is the arrival's (seen = before (L + 1) + slot + 1),
    # else -1 (a shallower one: seen is then at most before (L + 1) - 1)
    encl = (seen - (before * (L + 1) + 1)).clamp(min=-1)
    target = torch.where(close, encl[:, :L], L)
    end = torch.full((B, L + 1), L, dtype=torch.long, device=ops.device)
    end.scatter_(1, target, k.slot.expand(B, L))
    return close, encl, end[:, :L]


def compute_jumps(opcodes: torch.Tensor) -> torch.Tensor:
    """opcodes [..., L] -> jumps [..., L] long.

    SEQ / SEL at i: the index just past its matching END (L if unclosed); any other slot: i + 1.
    """
    shape = opcodes.shape
    L = shape[-1]
    B = math.prod(shape[:-1])
    ops = opcodes if opcodes.dim() == 2 else opcodes.reshape(B, L)
    ops = ops if ops.dtype == torch.long else ops.long()
    if L == 0 or B == 0:
        return ops.clone().reshape(shape)
    _, _, end = _nesting(ops)
    jumps = torch.where(ops <= SEL, (end + 1).clamp(max=L), _slots(L, ops.device).next_slot)
    return jumps if opcodes.dim() == 2 else jumps.reshape(shape)


def interpret(
    opcodes: torch.Tensor, jumps: torch.Tensor, leaf_status: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """opcodes, jumps [..., L], leaf_status [..., 14] -> action [...], fired [..., 14] bool,
    status [...].

    A stack machine run for a fixed 2L+1 steps (enough for any program), all updates masked.
    Each step either resolves a child's status against the innermost open block (short-circuit:
    pop it and jump to its end) or arrives at the slot ``pc`` (open a block, close one at END or at
    the end of the array, evaluate a leaf, skip NOP / stray END). A leaf returning RUNNING halts.
    Leaves are evaluated as given: a condition given RUNNING halts the tick like an action.
    """
    batch = opcodes.shape[:-1]
    L = opcodes.shape[-1]
    dev = opcodes.device
    pad = torch.full((*batch, 1), NOP, dtype=torch.long, device=dev)
    B = math.prod(batch)
    ops = torch.cat([opcodes.long(), pad], -1).reshape(B, L + 1)  # NOP sentinel at slot L
    jmp = torch.cat([jumps.long(), pad], -1).reshape(B, L + 1)
    ls = leaf_status.long().reshape(B, NUM_OPCODES)
    zeros = torch.zeros(B, dtype=torch.long, device=dev)
    pc, sp, r, fired_bits = zeros, zeros, zeros, zeros
    action = torch.full_like(zeros, NOP)
    status = torch.full_like(zeros, SUCCESS)
    stack = torch.zeros(B, L + 2, dtype=torch.long, device=dev)  # opener slots, stack[0] unused
    ret = torch.zeros(B, dtype=torch.bool, device=dev)  # a child just returned r
    done = torch.zeros_like(ret)
    for _ in range(2 * L + 1):
        top = _gather1(stack, sp)
        in_block = sp > 0
        btype = torch.where(in_block, _gather1(ops, top), SEQ)
        end = torch.where(in_block, _gather1(jmp, top), L)
        dflt = _default(btype)
        # Phase 1: resolve a returned status; a non-default status short-circuits the block.
        resolving = ~done & ret
        cont = resolving & (r == dflt)
        short = resolving & (r != dflt)
        root_short = short & ~in_block
        pop = short & in_block
        done = done | root_short
        status = torch.where(root_short, r, status)
        sp = sp - pop.long()
        pc = torch.where(pop, end, pc)
        ret = ret & ~cont
        # Phase 2: arrive at pc (rows that popped wait for the next step).
        arrive = ~done & ~ret
        op = _gather1(ops, pc)
        eof = pc >= L
        closing = arrive & (eof | ((op == END) & in_block))
        root_end = closing & ~in_block
        close = closing & in_block
        push = arrive & ~eof & (op <= SEL)
        leaf = arrive & ~eof & _is_leaf(op)
        st = _gather1(ls, torch.where(leaf, op, 0))
        halt = leaf & (st == RUNNING)
        leaf_ret = leaf & (st != RUNNING)
        fired_bits = fired_bits | ((leaf_ret & (st == SUCCESS) & _is_action(op)).long() << op)
        done = done | root_end | halt
        status = torch.where(root_end, SUCCESS, torch.where(halt, RUNNING, status))
        action = torch.where(halt, op, action)
        ret = ret | close | leaf_ret
        r = torch.where(close, dflt, torch.where(leaf_ret, st, r))
        sp = sp - close.long()
        pc = torch.where(close, end, torch.where(arrive & ~eof & ~halt, pc + 1, pc))
        sp = sp + push.long()
        stack = _set1(stack, sp, pc - 1, push)
    fired = (fired_bits.unsqueeze(-1) >> torch.arange(NUM_OPCODES, device=dev)) & 1
    return action.reshape(batch), fired.bool().reshape(*batch, NUM_OPCODES), status.reshape(batch)


def combo_index(leaf_status: torch.Tensor) -> torch.Tensor:
    """leaf_status [..., 14] -> combination index [...] long in [0, NUM_COMBOS).

    index = sum_k (status[2+k] == FAILURE) 2^k + 16 sum_j status[6+j] 3^j. Conditions never
    return RUNNING; a condition given RUNNING is treated as FAILURE here.
    """
    ls = leaf_status.long()
    dev = ls.device
    w2 = torch.tensor([1, 2, 4, 8], device=dev)
    w3 = torch.tensor([16, 48, 144, 432, 1296, 3888], device=dev)
    cond = (ls[..., COND_HAS_PACKAGE:ACT_MOVE_TO_PACK] != SUCCESS).long()
    act = ls[..., ACT_MOVE_TO_PACK:END]
    return (cond * w2).sum(-1) + (act * w3).sum(-1)


@functools.lru_cache(maxsize=8)
def _combo_columns(device: torch.device) -> torch.Tensor:
    """[14 * NUM_COMBOS] long: `combo_statuses` by opcode, then combination (the tables' column
    of each opcode; built once per device, never written to)."""
    return combo_statuses(device).t().reshape(-1).contiguous()


def combo_statuses(device: torch.device | str | None = None) -> torch.Tensor:
    """-> [NUM_COMBOS, 14] long: the leaf_status of every combination (non-leaf entries SUCCESS)."""
    c = torch.arange(NUM_COMBOS, device=device)
    out = torch.full((NUM_COMBOS, NUM_OPCODES), SUCCESS, dtype=torch.long, device=device)
    for k, op in enumerate(CONDITION_OPS):
        out[:, op] = (c >> k) & 1  # bit set = FAILURE
    a = c // 16
    for op in ACTION_OPS:
        out[:, op] = a % 3
        a = a // 3
    return out


def _continuations(ops: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """ops [P, L] -> start [P], cont [P, L, 2]: the first leaf / the leaf after leaf i on SUCCESS,
    FAILURE (rows of the other slots: as if that slot were a leaf; no walk reads them).

    Codes: 0..L-1 = visit that leaf slot next; L + s = the tick ends with root status s.
    Each program's control flow is a graph whose every node has one successor, resolved by
    pointer doubling (a fixed number of gathers, no loop over slots). Nodes: A(j), arriving at
    slot j (j = L: the array's end); T(e, s), the block closed by the END at e returns s to its
    parent (which continues after the END if s is its default, else returns s itself; a block
    with no closed parent ends the tick with root status s); the codes, which are final.
    """
    P, L = ops.shape
    if L == 0:  # the empty program: the root SEQ ends at once
        return ops.new_full((P,), SUCCESS), ops.new_zeros(P, 0, 2)
    k = _slots(L, ops.device)
    close, encl, end = _nesting(ops)
    n_t = L + 1  # first node of T(e, s)
    n_c = 3 * L + 1  # first code node
    # Blocks by column: the block opened at slot j < L, the root at column L (a block b >= 0 is
    # column b, the root b = -1 column L: b mod (L + 1)).
    dflt = F.pad(_default(ops), (0, 1), value=SUCCESS)  # [P, L + 1] (the root is a SEQ)
    # where a child's non-default status s goes: its block's T(END, s), the root's code L + s
    up = F.pad(torch.where(end < L, n_t + 2 * end, n_c + L), (0, 1), value=n_c + L)
    # [P, L + 1, 2]: a child of the block returns s: -1 to continue after the child (s is the
    # block's default), else the node it goes to
    outcome = torch.where(k.s == dflt[..., None], -1, up[..., None] + k.s)

    def returns(col: torch.Tensor) -> torch.Tensor:
        """[P, L] blocks' columns -> [P, L, 2]: a child of that block ending just before slot
        i + 1 returns s: continue there if s is the block's default, else the block returns s."""
        to = outcome.gather(1, col[..., None].expand(P, L, 2))
        return torch.where(to < 0, k.next_col, to)

    col = encl % (L + 1)  # [P, L + 1] the innermost open block's column
    enc = col[:, :L]
    parent = F.pad(enc, (0, 1), value=L).gather(1, enc)  # the enclosing block's own block
    enc_dflt = dflt.gather(1, col)  # [P, L + 1] the innermost open block's default
    arrive = torch.where(
        _is_leaf(ops), k.leaf_node, torch.where(close, k.end_node + enc_dflt[:, :L], k.next_slot)
    )
    at_end = n_c + L + enc_dflt[:, L:]
    ret = torch.where(close[..., None], returns(parent), k.root_codes)
    nxt = torch.cat(
        [arrive, at_end, ret.reshape(P, 2 * L), k.codes.expand(P, L + 2)], 1
    )  # [P, 4L + 3]
    for _ in range(nxt.shape[1].bit_length()):
        nxt = nxt.gather(1, nxt)
    cont = nxt.gather(1, returns(enc).reshape(P, 2 * L)).reshape(P, L, 2) - n_c
    return nxt[:, 0] - n_c, cont


def _build_chunk(ops: torch.Tensor, col_status: torch.Tensor, compact: bool = True) -> torch.Tensor:
    """ops [P, L], col_status [14 * NC] (status of opcode o under combo c at o*NC+c) -> int32
    [P, NC]."""
    P, L = ops.shape
    NC = NUM_COMBOS
    dev = ops.device
    start, cont = _continuations(ops)
    # States per program: 0..L-1 leaf slots, L / L+1 ended SUCCESS / FAILURE, L+2+i RUNNING at i.
    NS = 2 * L + 2
    base = (torch.arange(P, device=dev) * NS).unsqueeze(1)
    slot = torch.arange(L, device=dev)
    fire = torch.where(
        _is_action(ops), 1 << (_FIRED_SHIFT + (ops - ACT_MOVE_TO_PACK).clamp(min=0)), 0
    )
    nxt = torch.cat([cont, (L + 2 + slot).expand(P, L).unsqueeze(-1)], -1)  # [P, L, 3]
    word = (base.unsqueeze(-1) + nxt) << _CODE_SHIFT
    word[:, :, SUCCESS] |= fire
    term = (
        ((base + torch.arange(L, NS, device=dev)) << _CODE_SHIFT).unsqueeze(-1).expand(P, NS - L, 3)
    )
    trans = torch.cat([word, term], 1).reshape(-1)  # [P * NS * 3], terminal states loop
    colx = torch.cat([ops, torch.full((P, NS - L), NOP, device=dev)], 1) * NC
    colx = colx.reshape(-1)  # [P * NS], combo-table column of each state's opcode
    final = torch.full((P, NS), NOP, dtype=torch.long, device=dev)
    final[:, L] |= SUCCESS << _STATUS_SHIFT
    final[:, L + 1] |= FAILURE << _STATUS_SHIFT
    final[:, L + 2 :] = ops | (RUNNING << _STATUS_SHIFT)
    # Walk every (program, combination) pair; finished pairs are set aside after each step.
    g = (base + start.unsqueeze(1)).expand(P, NC).reshape(-1)  # current state, global index
    pos = torch.arange(P * NC, device=dev)  # flat output position of each walking pair
    acc = torch.zeros_like(g)  # fired bits so far
    fired_mask = 0x3F << _FIRED_SHIFT
    if not compact:
        # terminal states loop onto themselves and add no fired bits, so a finished pair can
        # keep stepping; a pair visits each leaf slot at most once, so L + 1 steps end them all
        combo = pos % NC
        for _ in range(L + 1):
            w = trans[g * 3 + col_status[colx[g] + combo]]
            g = w >> _CODE_SHIFT
            acc |= w
        return (final.reshape(-1)[g] | (acc & fired_mask)).to(torch.int32).reshape(P, NC)
    packed = torch.empty_like(g)
    terminal = NOP * NC
    for _ in range(L + 1):  # each step visits one leaf; a pair visits each slot at most once
        col = colx[g]
        live = col != terminal
        fin = (~live).nonzero().squeeze(1)
        packed[pos[fin]] = final.reshape(-1)[g[fin]] | (acc[fin] & fired_mask)
        keep = live.nonzero().squeeze(1)
        if keep.numel() == 0:
            break
        g, pos, acc, col = g[keep], pos[keep], acc[keep], col[keep]
        w = trans[g * 3 + col_status[col + pos % NC]]
        g = w >> _CODE_SHIFT
        acc |= w
    return packed.to(torch.int32).reshape(P, NC)


def build_tables(
    opcodes: torch.Tensor, chunk: int | None = None, compact: bool | None = None
) -> torch.Tensor:
    """opcodes [P, L] -> int32 [P, NUM_COMBOS]: packed interpret() result for every combination.

    Packing: bits 0-3 action, bit 4+j fired flag of action 6+j, bits 10-11 root status.
    Programs are walked `chunk` at a time over all combinations. `compact` sets finished
    (program, combination) pairs aside after each step, which saves work but syncs the device
    twice a step; without it every pair takes L + 1 steps with no sync (finished pairs stay put).
    Defaults: compact on the CPU, 32 programs a chunk; on a GPU no compaction, 512 a chunk. On
    the CPU with neither given, the walk runs in C++ where the fused tick's extension is built
    (`_native_tables`; identical tables).
    """
    ops = cast(opcodes, torch.long)
    on_cpu = ops.device.type == "cpu"
    if on_cpu and compact is None and chunk is None and ops.shape[0]:
        native = _native_tables(ops)
        if native is not None:
            return native
    compact = on_cpu if compact is None else compact
    chunk = chunk or (32 if on_cpu else 512)
    col_status = _combo_columns(ops.device)
    parts = [
        _build_chunk(ops[i : i + chunk], col_status, compact) for i in range(0, ops.shape[0], chunk)
    ]
    if not parts:
        return torch.zeros(0, NUM_COMBOS, dtype=torch.int32, device=ops.device)
    return torch.cat(parts, 0)


def _native_tables(ops: torch.Tensor) -> torch.Tensor | None:
    """`build_tables` on the CPU by the fused tick's C++ extension (`sim.fused`): the same walk
    over every (program, combination) pair, the same int32 words (tests/sim/test_bt.py). None where
    the extension is not built or not wanted (``SWARMCODE_TICK=reference``)."""
    from ..native import load_extension, tick_choice

    if tick_choice() != "fused":
        return None
    mod = load_extension()
    walk = getattr(mod, "walk_tables", None)
    if walk is None:
        return None
    start, cont = _continuations(ops)
    col_status = _combo_columns(ops.device)
    return walk(ops.contiguous(), start, cont, col_status)


def unpack(packed: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """packed [...] -> action [...] long, fired [..., 14] bool, status [...] long."""
    p = packed.long()
    shifts = torch.arange(NUM_OPCODES, device=p.device) - ACT_MOVE_TO_PACK + _FIRED_SHIFT
    shifts = torch.where(_is_action(torch.arange(NUM_OPCODES, device=p.device)), shifts, 31)
    fired = ((p.unsqueeze(-1) >> shifts) & 1).bool()
    return p & 0xF, fired, (p >> _STATUS_SHIFT) & 3


def lookup(
    tables: torch.Tensor, prog_idx: torch.Tensor, leaf_status: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """tables [P, NUM_COMBOS], prog_idx [...], leaf_status [..., 14] -> action [...],
    fired [..., 14], status [...]."""
    flat = prog_idx.long() * tables.shape[-1] + combo_index(leaf_status)
    return unpack(torch.take(tables, flat))
