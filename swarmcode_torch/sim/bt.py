"""Flattened behavior trees: opcodes, jump tables and a batched, masked interpreter.

The encoding follows the SwarmCoDe paper's opcode table (Wilhelm & Hughes).

A program is a LongTensor [..., L] of opcodes in pre-order: SEQ / SEL open a block, its children
follow, END closes the innermost open block. NOP is skipped (never a child), an END with no open
block is ignored, and blocks still open at the end of the array close there. Top-level nodes are
the children of an implicit root SEQ. Every array of opcodes 0..13 is a valid program.

* ``compute_jumps`` / ``interpret``: a batched, fixed-step, masked interpreter (torch.compile and
  CUDA-graph friendly: no data-dependent Python control flow, no host syncs).
* ``build_tables`` / ``lookup``: the fast path. Conditions return SUCCESS / FAILURE and actions
  SUCCESS / FAILURE / RUNNING, so a tick's outcome is one of NUM_COMBOS = 2^4 * 3^6 leaf-status
  combinations; ``build_tables`` precomputes every program's packed outcome for all of them once
  per generation, and ``lookup`` is then a single gather per robot per tick.
* ``interpret_reference`` / ``parse`` / ``format_tree``: plain-Python reference and printing.
* ``TEMPLATES``: the hand-made seed trees.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch

# Opcodes (the paper's table).
SEQ = 0
SEL = 1
COND_HAS_PACKAGE = 2
COND_NEAR_PACKAGE = 3
COND_NEAR_BASE = 4
COND_AM_I_STUCK = 5
ACT_MOVE_TO_PACK = 6
ACT_MOVE_TO_BASE = 7
ACT_RANDOM_WALK = 8
ACT_PICK_UP = 9
ACT_DROP = 10
ACT_MOVE_TO_RANDOM_PACK = 11
END = 12
NOP = 13
NUM_OPCODES = 14

# Statuses.
SUCCESS = 0
FAILURE = 1
RUNNING = 2

CONTROL_OPS = (SEQ, SEL)
CONDITION_OPS = (COND_HAS_PACKAGE, COND_NEAR_PACKAGE, COND_NEAR_BASE, COND_AM_I_STUCK)
ACTION_OPS = (
    ACT_MOVE_TO_PACK,
    ACT_MOVE_TO_BASE,
    ACT_RANDOM_WALK,
    ACT_PICK_UP,
    ACT_DROP,
    ACT_MOVE_TO_RANDOM_PACK,
)
LEAF_OPS = CONDITION_OPS + ACTION_OPS

OPCODE_NAMES = {
    SEQ: "SEQ",
    SEL: "SEL",
    COND_HAS_PACKAGE: "COND_HAS_PACKAGE",
    COND_NEAR_PACKAGE: "COND_NEAR_PACKAGE",
    COND_NEAR_BASE: "COND_NEAR_BASE",
    COND_AM_I_STUCK: "COND_AM_I_STUCK",
    ACT_MOVE_TO_PACK: "ACT_MOVE_TO_PACK",
    ACT_MOVE_TO_BASE: "ACT_MOVE_TO_BASE",
    ACT_RANDOM_WALK: "ACT_RANDOM_WALK",
    ACT_PICK_UP: "ACT_PICK_UP",
    ACT_DROP: "ACT_DROP",
    ACT_MOVE_TO_RANDOM_PACK: "ACT_MOVE_TO_RANDOM_PACK",
    END: "END",
    NOP: "NOP",
}

# ---------------------------------------------------------------------------------------------
# Helpers
# ---------------------------------------------------------------------------------------------

NUM_COMBOS = 2 ** len(CONDITION_OPS) * 3 ** len(ACTION_OPS)  # 11,664 leaf-status combinations

_FIRED_SHIFT = 4  # packed bits 4..9: fired flags of actions 6..11
_STATUS_SHIFT = 10  # packed bits 10..11: root status
_CODE_SHIFT = 16  # build_tables' internal transition words: next state << 16 | fired bits


def _default(block_type: torch.Tensor) -> torch.Tensor:
    """[...] -> [...]: a block's status when no child short-circuits it (SEQ: SUCCESS, SEL:
    FAILURE)."""
    return torch.where(block_type == SEL, FAILURE, SUCCESS)


def _is_leaf(op: torch.Tensor) -> torch.Tensor:
    """[...] -> [...] bool: opcode is a condition or an action."""
    return (op >= COND_HAS_PACKAGE) & (op <= ACT_MOVE_TO_RANDOM_PACK)


def _is_action(op: torch.Tensor) -> torch.Tensor:
    """[...] -> [...] bool: opcode is an action."""
    return (op >= ACT_MOVE_TO_PACK) & (op <= ACT_MOVE_TO_RANDOM_PACK)


def _gather1(t: torch.Tensor, idx: torch.Tensor) -> torch.Tensor:
    """t [B, N], idx [B] -> [B]: t[b, idx[b]]."""
    return t.gather(1, idx.unsqueeze(1)).squeeze(1)


def _set1(
    t: torch.Tensor, idx: torch.Tensor, value: torch.Tensor, mask: torch.Tensor
) -> torch.Tensor:
    """t [B, N] -> copy with t[b, idx[b]] = value[b] where mask[b]."""
    value = torch.where(mask, value, _gather1(t, idx))
    return t.scatter(1, idx.unsqueeze(1), value.unsqueeze(1))


# ---------------------------------------------------------------------------------------------
# Jumps and the batched, masked interpreter
# ---------------------------------------------------------------------------------------------


def compute_jumps(opcodes: torch.Tensor) -> torch.Tensor:
    """opcodes [..., L] -> jumps [..., L] long.

    SEQ / SEL at i: the index just past its matching END (L if unclosed); any other slot: i + 1.
    """
    shape = opcodes.shape
    L = shape[-1]
    B = math.prod(shape[:-1])
    ops = opcodes.reshape(B, L).long()
    dev = ops.device
    jumps = torch.arange(1, L + 1, device=dev).expand(B, L).clone()
    jumps = torch.where(ops <= SEL, L, jumps)
    stack = torch.zeros(B, L + 1, dtype=torch.long, device=dev)  # stack[d]: opener slot at depth d
    depth = torch.zeros(B, dtype=torch.long, device=dev)
    for i in range(L):
        op = ops[:, i]
        push = op <= SEL
        close = (op == END) & (depth > 0)
        opener = _gather1(stack, depth)
        jumps = _set1(jumps, opener, torch.full_like(opener, i + 1), close)
        depth = depth - close.long()
        depth = depth + push.long()
        stack = _set1(stack, depth, torch.full_like(depth, i), push)
    return jumps.reshape(shape)


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


def _node_name(op: int) -> str:
    """Opcode -> its name, e.g. "SEL"."""
    return OPCODE_NAMES.get(op, f"OP{op}")


# ---------------------------------------------------------------------------------------------
# Pure-Python reference (for tests)
# ---------------------------------------------------------------------------------------------

Node = int | tuple[int, list["Node"]]  # a leaf opcode, or (SEQ|SEL, children)


def parse(program: Sequence[int]) -> list[Node]:
    """Pre-order opcode list -> the implicit root's children (NOP skipped, stray END ignored):
    `parse_slots` without the slots. It keeps its own stack, as `format_tree`, `tree_lines` and
    `trace` do, so a tree nested thousands of levels deep (a 4096-slot program of SEQ, which a
    run file may hold) is read and shown without recursion; only the tests' reference `_eval`
    recurses."""
    root: list[Node] = []
    stack = [root]
    for op in (int(o) for o in program):
        if op == NOP:
            continue
        if op == END:
            if len(stack) > 1:
                stack.pop()
        elif op in CONTROL_OPS:
            children: list[Node] = []
            stack[-1].append((op, children))
            stack.append(children)
        else:
            stack[-1].append(op)
    return root


def _eval(node: Node, leaf_status: Sequence[int], fired: set[int]) -> tuple[int, int]:
    """Recursively tick one node -> (status, action of the RUNNING leaf or NOP): the plain
    reference the tests hold the interpreters to (`trace`, which replays use, keeps a stack)."""
    if isinstance(node, int):
        st = int(leaf_status[node])
        if st == RUNNING:
            return RUNNING, node
        if st == SUCCESS and node in ACTION_OPS:
            fired.add(node)
        return st, NOP
    op, children = node
    for child in children:
        st, act = _eval(child, leaf_status, fired)
        if st == RUNNING:
            return RUNNING, act
        if op == SEQ and st == FAILURE:
            return FAILURE, NOP
        if op == SEL and st == SUCCESS:
            return SUCCESS, NOP
    return (SUCCESS if op == SEQ else FAILURE), NOP


def interpret_reference(
    program: Sequence[int], leaf_status: Sequence[int]
) -> tuple[int, set[int], int]:
    """One program (list of opcodes), leaf_status (14 ints) -> (action, fired actions, root
    status)."""
    fired: set[int] = set()
    status, action = _eval((SEQ, parse(program)), leaf_status, fired)
    return action, fired, status


# ---------------------------------------------------------------------------------------------
# Fast path: per-program lookup tables over all leaf-status combinations
# ---------------------------------------------------------------------------------------------


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
    FAILURE.

    Codes: 0..L-1 = visit that leaf slot next; L + s = the tick ends with root status s.
    A forward pass records each slot's depth and enclosing block types; a backward pass keeps,
    per depth d, R[d, s] = where to go when the open block at depth d returns s.
    """
    P, L = ops.shape
    dev = ops.device
    ar = torch.arange(P, device=dev)
    depth = torch.zeros(P, dtype=torch.long, device=dev)
    types = torch.full((P, L + 2), SEQ, dtype=torch.long, device=dev)  # types[d]: block at depth d
    deps, btypes, ptypes, closes = [], [], [], []
    for i in range(L):
        op = ops[:, i]
        close = (op == END) & (depth > 0)
        deps.append(depth)
        btypes.append(types[ar, depth])
        ptypes.append(types[ar, (depth - 1).clamp(min=0)])
        closes.append(close)
        push = op <= SEL
        depth = depth - close.long() + push.long()
        types = _set1(types, depth, op, push)
    R = (L + torch.arange(2, device=dev)).expand(P, L + 1, 2).clone()  # unclosed: propagate to root
    nxt = L + _default(types[ar, depth])  # arriving at the array end closes the innermost block
    s = torch.arange(2, device=dev)
    cont = torch.zeros(P, L, 2, dtype=torch.long, device=dev)
    for i in reversed(range(L)):
        k = deps[i]
        d_blk = _default(btypes[i]).unsqueeze(1)
        d_par = _default(ptypes[i]).unsqueeze(1)
        r_k = R[ar, k]
        cont[:, i] = torch.where(s == d_blk, nxt.unsqueeze(1), r_k)
        new_r = torch.where(s == d_par, nxt.unsqueeze(1), R[ar, (k - 1).clamp(min=0)])
        close = closes[i]
        R[ar, k] = torch.where(close.unsqueeze(1), new_r, r_k)
        here = torch.where(close, new_r.gather(1, d_blk).squeeze(1), nxt)
        nxt = torch.where(_is_leaf(ops[:, i]), i, here)
    return nxt, cont


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
    ops = opcodes.long()
    on_cpu = ops.device.type == "cpu"
    if on_cpu and compact is None and chunk is None and ops.shape[0]:
        native = _native_tables(ops)
        if native is not None:
            return native
    compact = on_cpu if compact is None else compact
    chunk = chunk or (32 if on_cpu else 512)
    col_status = combo_statuses(ops.device).t().reshape(-1)
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
    from .native import load_extension, tick_choice

    if tick_choice() != "fused":
        return None
    mod = load_extension()
    walk = getattr(mod, "walk_tables", None)
    if walk is None:
        return None
    start, cont = _continuations(ops)
    col_status = combo_statuses(ops.device).t().reshape(-1).contiguous()
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


# ---------------------------------------------------------------------------------------------
# Templates, encoding, printing, random programs
# ---------------------------------------------------------------------------------------------


def _block(op: int, *children: int | list[int]) -> list[int]:
    """A control node with its children, closed by END, as a flat pre-order list."""
    out = [op]
    for c in children:
        out.extend(c if isinstance(c, list) else [c])
    return out + [END]


def _seq(*children: int | list[int]) -> list[int]:
    """SEQ(children...) as a flat pre-order list."""
    return _block(SEQ, *children)


def _sel(*children: int | list[int]) -> list[int]:
    """SEL(children...) as a flat pre-order list."""
    return _block(SEL, *children)


_DELIVER = _seq(COND_HAS_PACKAGE, ACT_MOVE_TO_BASE, ACT_DROP)
TEMPLATES: dict[str, list[int]] = {
    # Deliver if holding; else go to a package and pick it up; else wander.
    "forage": _sel(_DELIVER, _seq(ACT_MOVE_TO_PACK, ACT_PICK_UP), ACT_RANDOM_WALK),
    "forage_random": _sel(_DELIVER, _seq(ACT_MOVE_TO_RANDOM_PACK, ACT_PICK_UP), ACT_RANDOM_WALK),
    # A robot stuck holding a collaborative package lets go before trying to deliver.
    "collaborative": _sel(
        _seq(COND_HAS_PACKAGE, COND_AM_I_STUCK, ACT_DROP),
        _DELIVER,
        _seq(ACT_MOVE_TO_RANDOM_PACK, ACT_PICK_UP),
        ACT_RANDOM_WALK,
    ),
    # A stuck robot wanders off first; otherwise it forages.
    "cautious": _sel(
        _seq(COND_AM_I_STUCK, ACT_RANDOM_WALK),
        _DELIVER,
        _seq(ACT_MOVE_TO_PACK, ACT_PICK_UP),
        ACT_RANDOM_WALK,
    ),
}


def encode(nodes: Sequence[int], length: int) -> torch.Tensor:
    """Opcode list -> LongTensor [length], NOP padded; ValueError if longer than length."""
    if len(nodes) > length:
        raise ValueError(f"program of {len(nodes)} opcodes does not fit in length {length}")
    return torch.tensor(list(nodes) + [NOP] * (length - len(nodes)), dtype=torch.long)


def template_tensor(name: str, length: int) -> torch.Tensor:
    """Template name -> LongTensor [length] (NOP padded)."""
    return encode(TEMPLATES[name], length)


def format_tree(opcodes: torch.Tensor | Sequence[int], root: bool = True) -> str:
    """opcodes [L] -> an indented tree, one node per line, two spaces per level (NOP, END omitted).

    root (default): print the implicit root SEQ of the top-level nodes as the first line
    ("SEQ (root)") and indent them under it, so that the program reads as the one tree it runs
    as; False: the top-level nodes alone, each at the left margin (a forest).
    """
    program = opcodes.tolist() if isinstance(opcodes, torch.Tensor) else list(opcodes)
    lines = [text for text, _ in _slot_lines(program, 1 if root else 0)]
    return "\n".join(["SEQ (root)", *lines] if root else lines)


def _slot_lines(program: Sequence[int], level: int) -> list[tuple[str, int]]:
    """Each node of `program` in pre-order as (its line, indented two spaces per level from
    `level`, its slot): a walk with its own stack (no recursion, however deep the tree)."""
    lines: list[tuple[str, int]] = []
    todo: list[tuple[SlotNode, int]] = [(n, level) for n in reversed(parse_slots(program))]
    while todo:
        (slot, op, children), depth = todo.pop()
        lines.append(("  " * depth + _node_name(op), slot))
        todo.extend((c, depth + 1) for c in reversed(children))
    return lines


def random_programs(
    n: int, length: int, generator: torch.Generator | None = None, p_nop: float = 0.2
) -> torch.Tensor:
    """-> LongTensor [n, length]: NOP with probability p_nop, else uniform over opcodes 0..12."""
    ops = torch.randint(0, NOP, (n, length), generator=generator)
    nop = torch.rand(n, length, generator=generator) < p_nop
    return torch.where(nop, NOP, ops)


# ---------------------------------------------------------------------------------------------
# Tracing one tick (replays): which slots a tick visits, and the node that acted
# ---------------------------------------------------------------------------------------------

SlotNode = tuple[int, int, list]  # (slot of the node in the program array, opcode, children)


def parse_slots(program: Sequence[int]) -> list[SlotNode]:
    """Pre-order opcode list -> the implicit root's children as ``(slot, opcode, children)``
    (a leaf has no children; NOP skipped, stray END ignored); `parse` drops the slots."""
    root: list[SlotNode] = []
    stack = [root]
    for slot, op in enumerate(int(o) for o in program):
        if op == NOP:
            continue
        if op == END:
            if len(stack) > 1:
                stack.pop()
        elif op in CONTROL_OPS:
            children: list[SlotNode] = []
            stack[-1].append((slot, op, children))
            stack.append(children)
        else:
            stack[-1].append((slot, op, []))
    return root


def tree_lines(program: Sequence[int]) -> list[tuple[str, int]]:
    """``format_tree(program, root=True)``'s lines, each with the slot of its node (-1: the
    implicit root)."""
    return [("SEQ (root)", -1), *_slot_lines(program, 1)]


def trace(program: Sequence[int], leaf_status: Sequence[int]) -> tuple[int, list[tuple[int, int]]]:
    """One tick of one program, node by node (plain Python, for replays; the simulator itself
    runs :func:`lookup`, which it agrees with: tests/sim/test_bt.py).

    Returns ``(acting, visited)``: `visited` lists ``(slot, status)`` of every node the tick
    ticked, in the order they returned (a control node after its children; slot -1 is the
    implicit root), and `acting` is the slot of the node that acted: the leaf that returned
    RUNNING (the action the robot carries out), else the last action that succeeded (fired,
    e.g. a pick-up or a drop), else -1.
    """
    visited: list[tuple[int, int]] = []
    running = fired = -1  # the leaf that returned RUNNING, the last action that fired
    # frames of the control nodes being ticked: [node, index of its next child, its status]
    stack: list[list] = [[(-1, SEQ, parse_slots(program)), 0, SUCCESS]]
    returned: int | None = None  # the status the last finished child returned
    while stack:
        frame = stack[-1]
        slot, op, children = frame[0]
        if returned is not None:
            c, returned = returned, None
            if c == RUNNING or (op == SEQ and c == FAILURE) or (op == SEL and c == SUCCESS):
                frame[2] = c
                frame[1] = len(children)  # short-circuit: no further child is ticked
        if frame[1] < len(children):
            child = children[frame[1]]
            frame[1] += 1
            cslot, cop, _ = child
            if cop in CONTROL_OPS:
                stack.append([child, 0, SUCCESS if cop == SEQ else FAILURE])
            else:
                st = int(leaf_status[cop])
                visited.append((cslot, st))
                if st == RUNNING:
                    running = cslot
                elif st == SUCCESS and cop in ACTION_OPS:
                    fired = cslot
                returned = st
            continue
        visited.append((slot, frame[2]))
        stack.pop()
        returned = frame[2]
    return (running if running >= 0 else fired), visited
