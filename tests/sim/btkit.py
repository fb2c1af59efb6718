"""What the behavior-tree tests share: short names of statuses and actions, one tick of a
program through the interpreter, and the reference jump table."""

from __future__ import annotations

import torch

from swarmcode_torch.sim import bt
from swarmcode_torch.sim.bt import (
    ACT_MOVE_TO_BASE,
    ACT_MOVE_TO_PACK,
    ACT_RANDOM_WALK,
    COND_HAS_PACKAGE,
    COND_NEAR_PACKAGE,
    END,
    FAILURE,
    NUM_OPCODES,
    RUNNING,
    SEL,
    SEQ,
    SUCCESS,
    compute_jumps,
    interpret,
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
