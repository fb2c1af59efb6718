"""Signals: the steps of a run that Ctrl-C or SIGTERM must not split, the interrupt an
exception stands for, and the command line's one stop per process (`stop_once`): after the first
Ctrl-C or SIGTERM is acted on, later ones are ignored, so a second signal during the stop or the
interpreter's exit cannot kill the process by the signal (exit 130 or 143, the files whole)."""

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
            _restore(sig, h if h is not None else signal.SIG_DFL)
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
        stop_begun()
        raise KeyboardInterrupt

    try:
        previous = signal.signal(signal.SIGTERM, handler)
    except ValueError:  # not the main thread: leave signals alone
        yield terminated
        return
    try:
        yield terminated
    finally:
        _restore(signal.SIGTERM, previous)


#: The signals that stop a command.
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
#: Whether this process stops once (`stop_once`: the command line's own process), and whether
#: its stop has begun.
_ONCE = {"on": False, "stopping": False}


def stop_once() -> None:
    """For the command line's own process (`cli.main`), never a process that imports the package
    (a notebook must stay interruptible): the first Ctrl-C or SIGTERM that is acted on begins the
    stop (`stop_begun`), and from then on both are ignored until the process has exited, so a
    second one (0.05 s later, or while the interpreter exits after the last line) cannot cut
    the stop short or kill the process by the signal: the exit status is 130 or 143 and the run's
    files are whole. SIGKILL still ends a stop that hangs. Ctrl-C gets a handler that marks the
    stop and raises KeyboardInterrupt as Python's does; a process started with SIGINT ignored (a
    background job) keeps it ignored."""
    if threading.current_thread() is not threading.main_thread():
        return
    _ONCE["on"] = True
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        signal.signal(signal.SIGINT, _first_interrupt)


def _first_interrupt(signum, frame):
    stop_begun()
    raise KeyboardInterrupt


def stop_begun() -> None:
    """A stop has begun: in a process that stops once (`stop_once`), SIGINT and SIGTERM are
    ignored from now on (elsewhere nothing changes)."""
    if _ONCE["on"]:
        _ONCE["stopping"] = True
        ignore_stop_signals()


def ignore_stop_signals() -> None:
    """SIGINT and SIGTERM ignored (the main thread only; elsewhere signals cannot be set): a
    handler set to SIG_IGN stays so through the interpreter's exit, where a Python handler is
    put back to the default action."""
    if threading.current_thread() is not threading.main_thread():
        return
    for sig in STOP_SIGNALS:
        try:
            signal.signal(sig, signal.SIG_IGN)
        except (ValueError, OSError):  # pragma: no cover - no signals here
            pass


def _restore(sig: int, handler) -> None:
    """Put `handler` back for `sig`, unless this process's stop has begun (`stop_once`): then the
    stop signals stay ignored."""
    if _ONCE["stopping"] and sig in STOP_SIGNALS:
        handler = signal.SIG_IGN
    signal.signal(sig, handler)
