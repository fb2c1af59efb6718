"""Jumps and the batched, masked interpreter: fixed-step, no data-dependent Python control flow
and no host syncs (torch.compile and CUDA-graph friendly)."""

from __future__ import annotations

import math

import torch

from .ops import (
    END,
    NOP,
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
