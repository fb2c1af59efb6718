"""Tests of the behavior-tree programs (sim/bt/programs.py): templates, printing, tracing one
tick."""

from __future__ import annotations

import torch
from btkit import A, B, C, F, H, R, S, as_tuples, run, statuses

from swarmcode_torch.sim import bt
from swarmcode_torch.sim.bt import (
    ACT_DROP,
    ACT_MOVE_TO_PACK,
    ACT_MOVE_TO_RANDOM_PACK,
    ACT_PICK_UP,
    COND_HAS_PACKAGE,
    COND_NEAR_BASE,
    END,
    NOP,
    NUM_OPCODES,
    SEL,
    SEQ,
    TEMPLATES,
    build_tables,
    compute_jumps,
    encode,
    format_tree,
    interpret,
    interpret_reference,
    lookup,
    random_programs,
    template_tensor,
)

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
