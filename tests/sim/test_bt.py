"""Tests of the behavior-tree module: jumps, the masked interpreter, lookup tables, templates."""

from __future__ import annotations

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from swarmcode_torch.sim import bt
from swarmcode_torch.sim.bt import (
    ACT_DROP,
    ACT_MOVE_TO_BASE,
    ACT_MOVE_TO_PACK,
    ACT_MOVE_TO_RANDOM_PACK,
    ACT_PICK_UP,
    ACT_RANDOM_WALK,
    COND_AM_I_STUCK,
    COND_HAS_PACKAGE,
    COND_NEAR_BASE,
    COND_NEAR_PACKAGE,
    END,
    FAILURE,
    NOP,
    NUM_COMBOS,
    NUM_OPCODES,
    RUNNING,
    SEL,
    SEQ,
    SUCCESS,
    TEMPLATES,
    build_tables,
    combo_index,
    combo_statuses,
    compute_jumps,
    encode,
    format_tree,
    interpret,
    interpret_reference,
    lookup,
    random_programs,
    template_tensor,
    unpack,
)

S, F, R = SUCCESS, FAILURE, RUNNING
A, B, C = ACT_MOVE_TO_PACK, ACT_MOVE_TO_BASE, ACT_RANDOM_WALK  # short names for actions
H, N = COND_HAS_PACKAGE, COND_NEAR_PACKAGE


def statuses(**kw: int) -> list[int]:
    """A leaf_status list: every leaf SUCCESS unless given by opcode name (e.g. ACT_DROP=FAILURE)."""
    out = [S] * NUM_OPCODES
    for name, value in kw.items():
        out[getattr(bt, name)] = value
    return out


def run(program: list[int], ls: list[int]) -> tuple[int, set[int], int]:
    """interpret() on one program, as (action, fired set, status)."""
    ops = torch.tensor(program, dtype=torch.long)
    action, fired, status = interpret(ops, compute_jumps(ops), torch.tensor(ls))
    return int(action), {i for i in range(NUM_OPCODES) if fired[i]}, int(status)


def as_tuples(action, fired, status) -> list[tuple[int, set[int], int]]:
    """Batched interpret-style outputs [B] -> list of (action, fired set, status)."""
    fired_sets = [{i for i in range(NUM_OPCODES) if row[i]} for row in fired.tolist()]
    return list(zip(action.tolist(), fired_sets, status.tolist()))


def jumps_reference(program: list[int]) -> list[int]:
    """Straightforward stack-based jump computation."""
    out = [i + 1 for i in range(len(program))]
    stack: list[int] = []
    for i, op in enumerate(program):
        if op in (SEQ, SEL):
            out[i] = len(program)
            stack.append(i)
        elif op == END and stack:
            out[stack.pop()] = i + 1
    return out


# --- compute_jumps ------------------------------------------------------------------------------


def test_jumps_hand_made() -> None:
    cases = {
        # SEL( SEQ(H, A) , C )
        (SEL, SEQ, H, A, END, C, END): [7, 5, 3, 4, 5, 6, 7],
        # stray END first, then an unclosed SEQ with a NOP
        (END, SEQ, NOP, H): [1, 4, 3, 4],
        # nested unclosed blocks
        (SEL, SEQ, SEL): [3, 3, 3],
        # empty blocks and stray ENDs after closing
        (SEQ, END, SEL, END, END, END): [2, 2, 4, 4, 5, 6],
        (NOP, NOP): [1, 2],
    }
    for prog, expected in cases.items():
        got = compute_jumps(torch.tensor(prog)).tolist()
        assert got == expected, prog
        assert jumps_reference(list(prog)) == expected


def test_jumps_batched_and_shapes() -> None:
    g = torch.Generator().manual_seed(1)
    ops = random_programs(600, 17, g).reshape(20, 30, 17)
    jumps = compute_jumps(ops)
    assert jumps.shape == ops.shape and jumps.dtype == torch.long
    for prog, jmp in zip(ops.reshape(-1, 17).tolist(), jumps.reshape(-1, 17).tolist()):
        assert jmp == jumps_reference(prog)
    assert compute_jumps(torch.zeros(3, 0, dtype=torch.long)).shape == (3, 0)


# --- interpret on hand-made programs --------------------------------------------------------------


def test_interpret_hand_made() -> None:
    seq_h_a = [SEQ, H, A, END]
    # SEQ short-circuits on FAILURE; A is never visited.
    assert run(seq_h_a, statuses(COND_HAS_PACKAGE=F, ACT_MOVE_TO_PACK=R)) == (NOP, set(), F)
    # SEQ runs through; A fires.
    assert run(seq_h_a, statuses()) == (NOP, {A}, S)
    # RUNNING halts: the root is RUNNING, the action is reported.
    assert run(seq_h_a + [B], statuses(ACT_MOVE_TO_PACK=R)) == (A, set(), R)
    # SEL stops at the first SUCCESS.
    sel = [SEL, A, B, C, END]
    assert run(sel, statuses(ACT_MOVE_TO_PACK=F)) == (NOP, {B}, S)
    assert run(sel, statuses(ACT_MOVE_TO_PACK=F, ACT_MOVE_TO_BASE=F, ACT_RANDOM_WALK=F)) == (
        NOP,
        set(),
        F,
    )
    assert run(sel, statuses(ACT_MOVE_TO_PACK=F, ACT_MOVE_TO_BASE=R)) == (B, set(), R)
    # Empty blocks: SEQ succeeds, SEL fails; a failing top-level node fails the root.
    assert run([SEQ, END, A], statuses()) == (NOP, {A}, S)
    assert run([SEL, END, A], statuses()) == (NOP, set(), F)
    assert run([SEL, SEL, END, A, END], statuses()) == (NOP, {A}, S)
    assert run([], statuses()) == (NOP, set(), S)
    assert run([NOP, END, NOP], statuses()) == (NOP, set(), S)
    # NOPs are skipped wherever they are; stray ENDs are ignored.
    assert run([NOP, SEL, NOP, A, NOP, B, END, END, C], statuses(ACT_MOVE_TO_PACK=F)) == (
        NOP,
        {B, C},
        S,
    )
    # Unclosed blocks close at the array end: C is a child of the SEL.
    assert run([SEL, A, C], statuses()) == (NOP, {A}, S)
    assert run([SEL, A, C], statuses(ACT_MOVE_TO_PACK=F, ACT_RANDOM_WALK=F)) == (NOP, set(), F)
    # Conditions never fire; actions that fail do not fire.
    assert run([H, N, A], statuses(ACT_MOVE_TO_PACK=F)) == (NOP, set(), F)
    # A RUNNING deep inside a failing SEL still halts everything.
    assert run(
        [SEL, SEQ, H, END, SEQ, B, END, END], statuses(COND_HAS_PACKAGE=F, ACT_MOVE_TO_BASE=R)
    ) == (B, set(), R)
    # Nodes outside the program's opcode range are ignored: control / END / NOP statuses don't matter.
    ls = statuses()
    ls[SEQ] = ls[SEL] = ls[END] = ls[NOP] = R
    assert run([SEQ, A, END], ls) == (NOP, {A}, S)


def test_interpret_batch_dims() -> None:
    g = torch.Generator().manual_seed(2)
    ops = random_programs(4 * 5, 12, g).reshape(4, 5, 12)
    ls = torch.randint(0, 3, (4, 5, NUM_OPCODES), generator=g)
    action, fired, status = interpret(ops, compute_jumps(ops), ls)
    assert action.shape == (4, 5) and fired.shape == (4, 5, NUM_OPCODES) and status.shape == (4, 5)
    assert fired.dtype == torch.bool
    flat = as_tuples(action.reshape(-1), fired.reshape(-1, NUM_OPCODES), status.reshape(-1))
    for prog, st_row, got in zip(
        ops.reshape(-1, 12).tolist(), ls.reshape(-1, NUM_OPCODES).tolist(), flat
    ):
        assert got == interpret_reference(prog, st_row)


# --- interpret vs the reference -------------------------------------------------------------------

# Opcode mixes: uniform, control-heavy (deep nesting), END-heavy, NOP-heavy.
OPCODE_MIXES = [
    list(range(NUM_OPCODES)),
    [SEQ, SEL, SEQ, SEL, SEQ, SEL, COND_HAS_PACKAGE, ACT_DROP, END],
    [END, END, END, SEQ, SEL, ACT_PICK_UP, NOP],
    [NOP] * 6 + [SEQ, SEL, END, COND_NEAR_BASE, ACT_MOVE_TO_RANDOM_PACK],
    [END],
    [NOP],
]


@st.composite
def program_batches(draw) -> tuple[list[list[int]], list[list[int]]]:
    """A batch of 1..12 programs of one random length 0..40, with leaf statuses."""
    length = draw(st.integers(0, 40))
    n = draw(st.integers(1, 12))
    programs, status_rows = [], []
    for _ in range(n):
        mix = draw(st.sampled_from(OPCODE_MIXES))
        programs.append(draw(st.lists(st.sampled_from(mix), min_size=length, max_size=length)))
        status_rows.append(
            draw(st.lists(st.sampled_from([S, F, R]), min_size=NUM_OPCODES, max_size=NUM_OPCODES))
        )
    return programs, status_rows


@settings(max_examples=250, deadline=None)
@given(program_batches())
def test_interpret_matches_reference_hypothesis(batch) -> None:
    programs, status_rows = batch
    ops = torch.tensor(programs, dtype=torch.long).reshape(len(programs), -1)
    ls = torch.tensor(status_rows, dtype=torch.long)
    jumps = compute_jumps(ops)
    assert jumps.tolist() == [jumps_reference(p) for p in programs]
    got = as_tuples(*interpret(ops, jumps, ls))
    for prog, st_row, g in zip(programs, status_rows, got):
        assert g == interpret_reference(prog, st_row), (prog, st_row)
    # The lookup tables agree too (conditions given RUNNING count as FAILURE there).
    ls[:, 2:6] = torch.where(ls[:, 2:6] == R, F, ls[:, 2:6])
    want = interpret(ops, jumps, ls)
    got_lookup = lookup(build_tables(ops), torch.arange(len(programs)), ls)
    for w, x in zip(want, got_lookup):
        assert torch.equal(w, x)


def test_interpret_matches_reference_bulk() -> None:
    g = torch.Generator().manual_seed(3)
    ops = torch.cat(
        [random_programs(3000, 24, g, p_nop=0.2), random_programs(2000, 24, g, p_nop=0.6)]
    )
    ls = torch.randint(0, 3, (ops.shape[0], NUM_OPCODES), generator=g)
    got = as_tuples(*interpret(ops, compute_jumps(ops), ls))
    seen = set()
    for prog, st_row, res in zip(ops.tolist(), ls.tolist(), got):
        assert res == interpret_reference(prog, st_row), (prog, st_row)
        seen.add(res[2])
    assert seen == {S, F, R}


def test_worst_case_step_count() -> None:
    """Deepest unclosed nesting needs the full 2L+1 steps ([SEL] * 20 fails only on the last one)."""
    for prog in ([SEQ] * 20, [SEL] * 20, [SEL] * 19 + [A], [SEL, SEQ] * 10, [SEQ, SEL] * 10):
        for ls in (statuses(), statuses(ACT_MOVE_TO_PACK=F), statuses(ACT_MOVE_TO_PACK=R)):
            assert run(prog, ls) == interpret_reference(prog, ls), prog


# --- lookup tables -------------------------------------------------------------------------------


def test_combo_roundtrip() -> None:
    table = combo_statuses()
    assert table.shape == (NUM_COMBOS, NUM_OPCODES) and NUM_COMBOS == 11664
    assert torch.equal(combo_index(table), torch.arange(NUM_COMBOS))
    assert len({tuple(r) for r in table.tolist()}) == NUM_COMBOS
    non_leaf = [SEQ, SEL, END, NOP]
    assert (table[:, non_leaf] == S).all()
    assert (table[:, 2:6] <= F).all() and (table[:, 6:12] <= R).all()
    # Conditions given RUNNING count as FAILURE; non-leaf entries are ignored.
    ls = statuses(COND_NEAR_PACKAGE=R, ACT_DROP=R)
    ls[SEQ] = F
    fixed = statuses(COND_NEAR_PACKAGE=F, ACT_DROP=R)
    assert combo_index(torch.tensor(ls)) == combo_index(torch.tensor(fixed))
    assert combo_index(torch.tensor([ls, fixed])).shape == (2,)


def test_build_tables_all_combos_match_interpret() -> None:
    g = torch.Generator().manual_seed(4)
    long_walk = [
        SEQ,
        SEL,
        H,
        A,
        END,
        SEL,
        N,
        B,
        END,
        C,
        ACT_PICK_UP,
        SEL,
        ACT_DROP,
        COND_NEAR_BASE,
        ACT_MOVE_TO_RANDOM_PACK,
        COND_AM_I_STUCK,
        END,
        SEQ,
        A,
        B,
    ]  # many leaves on one path
    ops = torch.cat(
        [
            random_programs(2, 20, g),
            template_tensor("collaborative", 20)[None],
            encode(long_walk, 20)[None],
        ]
    )
    tables = build_tables(ops)
    assert tables.shape == (4, NUM_COMBOS) and tables.dtype == torch.int32
    combos = combo_statuses()
    for k in range(4):
        prog = ops[k].expand(NUM_COMBOS, -1)
        want = interpret(prog, compute_jumps(prog), combos)
        got = unpack(tables[k])
        for w, x in zip(want, got):
            assert torch.equal(w, x)


def test_lookup_matches_interpret_random() -> None:
    g = torch.Generator().manual_seed(5)
    P, L, robots = 40, 20, 6000
    ops = torch.cat(
        [random_programs(P - 4, L, g), torch.stack([template_tensor(n, L) for n in TEMPLATES])]
    )
    tables = build_tables(ops, chunk=7)  # odd chunk size exercises chunking
    assert torch.equal(tables, build_tables(ops))
    # the GPU's walk (no compaction, no device sync) gives the same tables
    assert torch.equal(tables, build_tables(ops, chunk=9, compact=False))
    prog_idx = torch.randint(0, P, (2, robots // 2), generator=g)
    ls = torch.randint(0, 3, (2, robots // 2, NUM_OPCODES), generator=g)
    cond = ls[..., 2:6] == R
    ls_fixed = ls.clone()
    ls_fixed[..., 2:6] = torch.where(
        cond, F, ls[..., 2:6]
    )  # lookup treats RUNNING conditions as FAILURE
    want = interpret(ops[prog_idx], compute_jumps(ops)[prog_idx], ls_fixed)
    got = lookup(tables, prog_idx, ls)
    for w, x in zip(want, got):
        assert w.shape == x.shape and w.dtype == x.dtype
        assert torch.equal(w, x)


def test_tables_of_deep_and_ragged_trees_match_interpret() -> None:
    """The tables' control flow (`_continuations`, resolved without a loop over slots) on trees
    of many blocks, nested deep, with stray and missing ENDs, against the interpreter."""
    g = torch.Generator().manual_seed(11)
    weights = torch.tensor([4.0, 4.0] + [1.0] * 10 + [5.0, 1.0])  # many SEQ / SEL and END
    P, L, robots = 60, 48, 4000
    ops = torch.multinomial(weights, P * L, replacement=True, generator=g).view(P, L)
    ops[0] = SEL
    ops[1, : L // 2], ops[1, L // 2 :] = SEQ, END
    ops[2, :] = END
    tables = build_tables(ops, chunk=16)
    assert torch.equal(tables, build_tables(ops, chunk=16, compact=False))
    prog_idx = torch.randint(0, P, (robots,), generator=g)
    ls = torch.randint(0, 3, (robots, NUM_OPCODES), generator=g)
    ls[:, 2:6] = ls[:, 2:6].clamp(max=F)  # conditions SUCCESS / FAILURE only
    want = interpret(ops[prog_idx], compute_jumps(ops)[prog_idx], ls)
    for w, x in zip(want, lookup(tables, prog_idx, ls)):
        assert torch.equal(w, x)


@pytest.mark.parametrize("compact", [True, False])
def test_build_tables_edge_cases(compact) -> None:
    assert build_tables(torch.zeros(0, 8, dtype=torch.long), compact=compact).shape == (
        0,
        NUM_COMBOS,
    )
    for ops in (
        torch.zeros(2, 0, dtype=torch.long),
        torch.full((2, 5), NOP),
        torch.full((2, 5), END),
    ):
        action, fired, status = unpack(build_tables(ops, compact=compact))
        assert (action == NOP).all() and not fired.any() and (status == S).all()
    action, _, status = unpack(build_tables(torch.full((1, 6), SEL), compact=compact))
    assert (action == NOP).all() and (status == F).all()


# --- templates and printing ----------------------------------------------------------------------

EXPECTED_TREES = {
    "forage": """SEL
  SEQ
    COND_HAS_PACKAGE
    ACT_MOVE_TO_BASE
    ACT_DROP
  SEQ
    ACT_MOVE_TO_PACK
    ACT_PICK_UP
  ACT_RANDOM_WALK""",
    "forage_random": """SEL
  SEQ
    COND_HAS_PACKAGE
    ACT_MOVE_TO_BASE
    ACT_DROP
  SEQ
    ACT_MOVE_TO_RANDOM_PACK
    ACT_PICK_UP
  ACT_RANDOM_WALK""",
    "collaborative": """SEL
  SEQ
    COND_HAS_PACKAGE
    COND_AM_I_STUCK
    ACT_DROP
  SEQ
    COND_HAS_PACKAGE
    ACT_MOVE_TO_BASE
    ACT_DROP
  SEQ
    ACT_MOVE_TO_RANDOM_PACK
    ACT_PICK_UP
  ACT_RANDOM_WALK""",
    "cautious": """SEL
  SEQ
    COND_AM_I_STUCK
    ACT_RANDOM_WALK
  SEQ
    COND_HAS_PACKAGE
    ACT_MOVE_TO_BASE
    ACT_DROP
  SEQ
    ACT_MOVE_TO_PACK
    ACT_PICK_UP
  ACT_RANDOM_WALK""",
}


def test_templates_parse() -> None:
    assert set(EXPECTED_TREES) <= set(TEMPLATES)
    for name, tree in EXPECTED_TREES.items():
        assert format_tree(TEMPLATES[name], root=False) == tree
        assert format_tree(template_tensor(name, 32), root=False) == tree
        assert TEMPLATES[name][-1] == END and TEMPLATES[name].count(END) == TEMPLATES[name].count(
            SEL
        ) + TEMPLATES[name].count(SEQ)


def test_format_tree_rules() -> None:
    prog = [END, NOP, SEQ, SEL, END, COND_NEAR_BASE, END, END, SEL, ACT_PICK_UP, SEQ]
    forest = "SEQ\n  SEL\n  COND_NEAR_BASE\nSEL\n  ACT_PICK_UP\n  SEQ"
    assert format_tree(prog, root=False) == forest
    assert format_tree([NOP, END], root=False) == ""
    # by default, the implicit root: the top-level nodes are its children, one tree
    tree = format_tree(prog)
    assert tree == format_tree(prog, root=True)
    assert tree == "SEQ (root)\n" + "\n".join("  " + line for line in forest.splitlines())
    lines = tree.splitlines()
    assert sum(not line.startswith(" ") for line in lines) == 1  # a single root
    assert format_tree([NOP]) == "SEQ (root)"


def test_encode() -> None:
    t = encode([SEQ, H, END], 5)
    assert t.dtype == torch.long and t.tolist() == [SEQ, H, END, NOP, NOP]
    try:
        encode([SEQ, H, END], 2)
    except ValueError:
        pass
    else:
        raise AssertionError("encode must refuse a program longer than length")


def tick(name: str, **kw: int) -> tuple[int, set[int], int]:
    """Tick a template with the given statuses via interpret, checked against lookup and the reference."""
    ls = statuses(**kw)
    res = run(TEMPLATES[name], ls)
    assert res == interpret_reference(TEMPLATES[name], ls)
    tables = build_tables(template_tensor(name, 24)[None])
    assert as_tuples(*lookup(tables, torch.zeros(1, dtype=torch.long), torch.tensor([ls]))) == [res]
    return res


def test_template_behavior() -> None:
    for name, fetch in (
        ("forage", "ACT_MOVE_TO_PACK"),
        ("forage_random", "ACT_MOVE_TO_RANDOM_PACK"),
    ):
        fetch_op = getattr(bt, fetch)
        # Holding, not at base: head home.
        assert tick(name, ACT_MOVE_TO_BASE=R) == (B, set(), R)
        # Holding, at base: drop (both actions succeeded this tick).
        assert tick(name) == (NOP, {B, ACT_DROP}, S)
        # Not holding, a package is far: go to it.
        assert tick(name, COND_HAS_PACKAGE=F, **{fetch: R}) == (fetch_op, set(), R)
        # Not holding, within reach: pick it up.
        assert tick(name, COND_HAS_PACKAGE=F) == (NOP, {fetch_op, ACT_PICK_UP}, S)
        # Not holding, no package left: random walk.
        assert tick(name, COND_HAS_PACKAGE=F, ACT_RANDOM_WALK=R, **{fetch: F}) == (C, set(), R)
        # The pick-up failed: random walk.
        assert tick(name, COND_HAS_PACKAGE=F, ACT_PICK_UP=F, ACT_RANDOM_WALK=R) == (
            C,
            {fetch_op},
            R,
        )
    # Collaborative: a stuck robot holding a package lets go.
    assert tick("collaborative", ACT_MOVE_TO_BASE=R) == (NOP, {ACT_DROP}, S)
    assert tick("collaborative", COND_AM_I_STUCK=F, ACT_MOVE_TO_BASE=R) == (B, set(), R)
    assert tick("collaborative", COND_HAS_PACKAGE=F, ACT_MOVE_TO_RANDOM_PACK=R) == (
        ACT_MOVE_TO_RANDOM_PACK,
        set(),
        R,
    )
    # Cautious: a stuck robot walks away first, else forages.
    assert tick("cautious", ACT_RANDOM_WALK=R) == (C, set(), R)
    assert tick("cautious", COND_AM_I_STUCK=F, ACT_MOVE_TO_BASE=R) == (B, set(), R)
    assert tick("cautious", COND_AM_I_STUCK=F, COND_HAS_PACKAGE=F, ACT_MOVE_TO_PACK=R) == (
        A,
        set(),
        R,
    )


def test_random_programs() -> None:
    a = random_programs(50, 16, torch.Generator().manual_seed(7), p_nop=0.5)
    b = random_programs(50, 16, torch.Generator().manual_seed(7), p_nop=0.5)
    assert torch.equal(a, b) and a.shape == (50, 16) and a.dtype == torch.long
    assert a.min() >= 0 and a.max() <= NOP
    assert (random_programs(5, 4, p_nop=1.0) == NOP).all()


def test_no_graph_breaks() -> None:
    """interpret, compute_jumps and lookup trace as a single graph (no data-dependent control flow)."""
    torch._dynamo.reset()
    ops = torch.tensor([[SEL, SEQ, H, B, END, C, END], [SEQ, END, NOP, A, SEL, END, END]])
    ls = torch.tensor([statuses(ACT_MOVE_TO_BASE=R), statuses(ACT_MOVE_TO_PACK=R)])
    f = torch.compile(
        lambda o, s: interpret(o, compute_jumps(o), s), backend="eager", fullgraph=True
    )
    for w, x in zip(interpret(ops, compute_jumps(ops), ls), f(ops, ls)):
        assert torch.equal(w, x)
    tables = build_tables(ops)
    idx = torch.tensor([1, 0])
    lk = torch.compile(lookup, backend="eager", fullgraph=True)
    for w, x in zip(lookup(tables, idx, ls), lk(tables, idx, ls)):
        assert torch.equal(w, x)


# ------------------------------------------------------------------ tracing one tick (replays)
def test_tree_lines_are_format_tree_with_slots() -> None:
    g = torch.Generator().manual_seed(5)
    progs = [bt.TEMPLATES[k] for k in bt.TEMPLATES] + random_programs(300, 24, g).tolist()
    for prog in progs:
        lines = bt.tree_lines(prog)
        assert "\n".join(text for text, _ in lines) == bt.format_tree(prog, root=True)
        assert lines[0][1] == -1
        for text, slot in lines[1:]:
            assert text.strip() == bt.OPCODE_NAMES[prog[slot]]


def test_trace_agrees_with_the_interpreter_and_the_tables() -> None:
    g = torch.Generator().manual_seed(9)
    ops = torch.cat(
        [
            random_programs(1500, 24, g, p_nop=0.2),
            torch.stack([bt.template_tensor(k, 24) for k in bt.TEMPLATES]),
        ]
    )
    ls = bt.combo_statuses()[torch.randint(0, bt.NUM_COMBOS, (ops.shape[0],), generator=g)]
    tables = bt.build_tables(ops)
    action, fired, status = bt.lookup(tables, torch.arange(ops.shape[0]), ls)
    for i, (prog, st_row) in enumerate(zip(ops.tolist(), ls.tolist())):
        acting, visited = bt.trace(prog, st_row)
        ref_action, ref_fired, ref_status = interpret_reference(prog, st_row)
        assert visited[-1] == (-1, ref_status) == (-1, int(status[i]))
        leaves = [(s, st) for s, st in visited if s >= 0 and prog[s] in bt.LEAF_OPS]
        assert {prog[s] for s, st in leaves if st == S and prog[s] in bt.ACTION_OPS} == ref_fired
        assert ref_fired == {k for k in range(NUM_OPCODES) if fired[i, k]}
        assert len({s for s, _ in visited}) == len(visited)  # each node ticks at most once
        if ref_status == R:
            assert prog[acting] == ref_action == int(action[i])
            assert leaves[-1] == (acting, R)
        elif ref_fired:
            assert prog[acting] in ref_fired
            assert acting == max(s for s, st in leaves if st == S and prog[s] in bt.ACTION_OPS)
        else:
            assert acting == -1


def test_trace_hand_made() -> None:
    prog = bt.TEMPLATES["forage"]  # SEL(SEQ(HAS, TO_BASE, DROP), SEQ(TO_PACK, PICK), WALK)
    acting, visited = bt.trace(prog, statuses(COND_HAS_PACKAGE=F, ACT_MOVE_TO_PACK=R))
    assert prog[acting] == ACT_MOVE_TO_PACK
    assert [prog[s] if s >= 0 else "root" for s, _ in visited] == [
        COND_HAS_PACKAGE,
        bt.SEQ,
        ACT_MOVE_TO_PACK,
        bt.SEQ,
        bt.SEL,
        "root",
    ]
    assert [st for _, st in visited] == [F, F, R, R, R, R]
    acting, visited = bt.trace(prog, statuses())  # holding, at the base: drop fires
    assert prog[acting] == ACT_DROP and visited[-1] == (-1, S)
