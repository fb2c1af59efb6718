"""Tests of the behavior-tree interpreter (sim/bt/batched.py): jumps, the masked interpreter,
lookup tables."""

from __future__ import annotations

import pytest
import torch
from btkit import A, B, C, F, H, N, R, S, as_tuples, jumps_reference, run, statuses
from hypothesis import given, settings
from hypothesis import strategies as st

from swarmcode_torch.sim.bt import (
    ACT_DROP,
    ACT_MOVE_TO_RANDOM_PACK,
    ACT_PICK_UP,
    COND_AM_I_STUCK,
    COND_HAS_PACKAGE,
    COND_NEAR_BASE,
    END,
    NOP,
    NUM_COMBOS,
    NUM_OPCODES,
    SEL,
    SEQ,
    TEMPLATES,
    build_tables,
    combo_index,
    combo_statuses,
    compute_jumps,
    encode,
    interpret,
    interpret_reference,
    lookup,
    random_programs,
    template_tensor,
    unpack,
)

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
