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
The module is split by job: `ops` (opcodes, statuses, the packed word), `interpreter`
(`compute_jumps`, `interpret`), `tables` (`build_tables`, `lookup`) and `programs` (the reference,
templates, printing, `trace`); every public name is importable from here.
"""

from .interpreter import compute_jumps, interpret
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
    COND_NEAR_BASE,
    COND_NEAR_PACKAGE,
    CONDITION_OPS,
    CONTROL_OPS,
    END,
    FAILURE,
    LEAF_OPS,
    NOP,
    NUM_COMBOS,
    NUM_OPCODES,
    OPCODE_NAMES,
    RUNNING,
    SEL,
    SEQ,
    SUCCESS,
)
from .programs import (
    TEMPLATES,
    Node,
    SlotNode,
    encode,
    format_tree,
    interpret_reference,
    parse,
    parse_slots,
    random_programs,
    template_tensor,
    trace,
    tree_lines,
)
from .tables import build_tables, combo_index, combo_statuses, lookup, unpack

__all__ = [
    "ACTION_OPS",
    "ACT_DROP",
    "ACT_MOVE_TO_BASE",
    "ACT_MOVE_TO_PACK",
    "ACT_MOVE_TO_RANDOM_PACK",
    "ACT_PICK_UP",
    "ACT_RANDOM_WALK",
    "CONDITION_OPS",
    "COND_AM_I_STUCK",
    "COND_HAS_PACKAGE",
    "COND_NEAR_BASE",
    "COND_NEAR_PACKAGE",
    "CONTROL_OPS",
    "END",
    "FAILURE",
    "LEAF_OPS",
    "NOP",
    "NUM_COMBOS",
    "NUM_OPCODES",
    "Node",
    "OPCODE_NAMES",
    "RUNNING",
    "SEL",
    "SEQ",
    "SUCCESS",
    "SlotNode",
    "TEMPLATES",
    "build_tables",
    "combo_index",
    "combo_statuses",
    "compute_jumps",
    "encode",
    "format_tree",
    "interpret",
    "interpret_reference",
    "lookup",
    "parse",
    "parse_slots",
    "random_programs",
    "template_tensor",
    "trace",
    "tree_lines",
    "unpack",
]
