"""Programs as text and as plain Python: the reference interpreter the tests hold the fast paths
to, the seed templates, encoding and printing, random programs, and tracing one tick node by
node (replays)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import torch

from .ops import (
    ACT_DROP,
    ACT_MOVE_TO_BASE,
    ACT_MOVE_TO_PACK,
    ACT_MOVE_TO_RANDOM_PACK,
    ACT_PICK_UP,
    ACT_RANDOM_WALK,
    ACTION_OPS,
    COND_AM_I_STUCK,
    COND_HAS_PACKAGE,
    CONTROL_OPS,
    END,
    FAILURE,
    NOP,
    RUNNING,
    SEL,
    SEQ,
    SUCCESS,
    _node_name,
)

# ---------------------------------------------------------------------------------------------
# Pure-Python reference (for tests)
# ---------------------------------------------------------------------------------------------

Node = int | tuple[int, list["Node"]]  # a leaf opcode, or (SEQ|SEL, children)


def _build(program: Sequence[int], node: Callable[[int, int, list | None], Any]) -> list:
    """Pre-order opcode list -> the implicit root's children, each made by `node(slot, opcode,
    children)` (children: None for a leaf; NOP skipped, stray END ignored). It keeps its own
    stack, as `format_tree`, `tree_lines` and `trace` do, so a tree nested thousands of levels
    deep (a 4096-slot program of SEQ, which a run file may hold) is read and shown without
    recursion; only the tests' reference `_eval` recurses."""
    root: list = []
    stack = [root]
    for slot, op in enumerate(int(o) for o in program):
        if op == NOP:
            continue
        if op == END:
            if len(stack) > 1:
                stack.pop()
        elif op in CONTROL_OPS:
            children: list = []
            stack[-1].append(node(slot, op, children))
            stack.append(children)
        else:
            stack[-1].append(node(slot, op, None))
    return root


def parse(program: Sequence[int]) -> list[Node]:
    """Pre-order opcode list -> the implicit root's children (NOP skipped, stray END ignored):
    `parse_slots` without the slots; no recursion, however deep the tree (`_build`)."""
    return _build(program, lambda slot, op, children: op if children is None else (op, children))


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
    """A behavior tree as an indented tree, one node per line, two spaces per level.

    Args:
        opcodes: the program [L] (NOP and END are omitted).
        root: print the implicit root SEQ of the top-level nodes as the first line ("SEQ (root)")
            and indent them under it, so that the program reads as the one tree it runs as;
            False: the top-level nodes alone, each at the left margin (a forest).

    Returns:
        The tree as text.
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
    return _build(
        program, lambda slot, op, children: (slot, op, [] if children is None else children)
    )


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
