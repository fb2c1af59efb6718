"""Opcodes, statuses and the packed-word layout of the behavior trees, and the small tensor
helpers the interpreter and the tables share."""

from __future__ import annotations

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


def _node_name(op: int) -> str:
    """Opcode -> its name, e.g. "SEL"."""
    return OPCODE_NAMES.get(op, f"OP{op}")


__all__ = [
    "SEQ",
    "SEL",
    "COND_HAS_PACKAGE",
    "COND_NEAR_PACKAGE",
    "COND_NEAR_BASE",
    "COND_AM_I_STUCK",
    "ACT_MOVE_TO_PACK",
    "ACT_MOVE_TO_BASE",
    "ACT_RANDOM_WALK",
    "ACT_PICK_UP",
    "ACT_DROP",
    "ACT_MOVE_TO_RANDOM_PACK",
    "END",
    "NOP",
    "NUM_OPCODES",
    "SUCCESS",
    "FAILURE",
    "RUNNING",
    "CONTROL_OPS",
    "CONDITION_OPS",
    "ACTION_OPS",
    "LEAF_OPS",
    "OPCODE_NAMES",
    "NUM_COMBOS",
]
