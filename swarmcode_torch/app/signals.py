"""Signals: the steps of a run that Ctrl-C or SIGTERM must not split, and the interrupt an
exception stands for."""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager


@contextmanager
def deferred_signals(deliver: bool = True) -> Iterator[list[int]]:
    """Within the block Ctrl-C (SIGINT) and SIGTERM are held, not acted on: a step that must
    not be split (a generation's records and its checkpoint; the checkpoint written on an
    interrupt) completes, then the first held signal is delivered to the handler that was in
    place (Ctrl-C's KeyboardInterrupt, the CLI's SIGTERM handler, or the default action). Off
    the main thread signals cannot be handled and the block runs as it is. `deliver=False`:
    held signals are dropped (a second Ctrl-C while a stopping run writes its checkpoint or
    closes its files: the stop is under way). Yields the list of held signal numbers."""
    held: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        yield held
        return

    def hold(signum, frame):
        held.append(signum)

    previous = {}
    try:
        for sig in (signal.SIGINT, signal.SIGTERM):
            previous[sig] = signal.signal(sig, hold)
    except (ValueError, OSError):  # pragma: no cover - no signals here
        for sig, h in previous.items():
            signal.signal(sig, h)
        yield held
        return
    failed = True
    try:
        yield held
        failed = False
    finally:
        for sig, h in previous.items():
            signal.signal(sig, h if h is not None else signal.SIG_DFL)
        if held and deliver and not failed:  # an error in the block is reported, not replaced
            sig = held[0]
            h = previous.get(sig)
            if callable(h):
                h(sig, None)
            elif h != signal.SIG_IGN:
                signal.raise_signal(sig)  # the default action, as if it arrived now


def interrupt_of(e: BaseException) -> KeyboardInterrupt | None:
    """The KeyboardInterrupt (Ctrl-C, or SIGTERM turned into one) that `e` is or was raised
    from, else None: an interrupt that lands while a compiled extension module initialises
    (matplotlib's, imported for the first figure) reaches Python as an ImportError caused by it."""
    seen = 0
    while e is not None and seen < 16:
        if isinstance(e, KeyboardInterrupt):
            return e
        e, seen = e.__cause__ or e.__context__, seen + 1
    return None


#: Set once SIGTERM has arrived in this process (the exit status is then 143, not 130).
TERMINATED: list[int] = []


@contextmanager
def terminate_as_interrupt():
    """Within the block SIGTERM (a scheduler's or `kill`'s stop) acts as Ctrl-C: the run writes
    the checkpoint of its last finished generation. A second SIGTERM while that checkpoint is
    written is ignored, so the write completes. Yields a list that is non-empty once SIGTERM
    has arrived."""
    terminated: list[int] = []

    def handler(signum, frame):
        if terminated:
            return  # already stopping: let the checkpoint be written
        terminated.append(signum)
        TERMINATED.append(signum)
        raise KeyboardInterrupt

    try:
        previous = signal.signal(signal.SIGTERM, handler)
    except ValueError:  # not the main thread: leave signals alone
        yield terminated
        return
    try:
        yield terminated
    finally:
        signal.signal(signal.SIGTERM, previous)
