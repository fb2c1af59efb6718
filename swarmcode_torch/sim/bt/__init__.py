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
The module is split by job: `ops` (opcodes, statuses, the packed word), `batched`
(`compute_jumps`, `interpret`, `build_tables`, `lookup`) and `programs` (the reference,
templates, printing, `trace`); every public name is importable from here.
"""

from .batched import (
    build_tables,
    combo_index,
    combo_statuses,
    compute_jumps,
    interpret,
    lookup,
    unpack,
)
from .ops import *  # noqa: F403 (every opcode, status and group: ops.__all__)
from .ops import __all__ as _ops_names
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

__all__ = [
    *_ops_names,
    "Node",
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
