"""The consoles of the command line and its one-line errors: `fail` (exit 2), a path option
checked (`check_path`), an OSError named with what was being done (`os_fail`)."""

from __future__ import annotations

import sys
from pathlib import Path

import typer
from rich.console import Console
from rich.markup import escape

# off a terminal (logs, pipes) Rich would wrap at 80 columns; tables need a little more
console = Console(width=None if sys.stdout.isatty() else 120)
err = Console(stderr=True, width=None if sys.stderr.isatty() else 200)


class Failed(typer.Exit):
    """The exit (code 2) of `fail`; `message` is its line (a sweep's Ray task reports it)."""

    def __init__(self, message: str):
        super().__init__(code=2)
        self.message = message


def fail(msg: str) -> None:
    """Print a one-line error and exit non-zero. The message is printed as it is: brackets such
    as [low, high] or [[packages]] are not read as Rich markup; a newline inside it becomes a
    space, so the error stays on one line."""
    msg = " ".join(str(msg).split())
    err.print(f"[bold red]Error:[/] {escape(msg)}", highlight=False, soft_wrap=True)
    raise Failed(msg)


#: The longest path an option takes (PATH_MAX).
MAX_PATH = 4096


def check_path(value: str | None, option: str) -> Path | None:
    """An option's path, checked: not empty (an empty --logdir would write into the working
    directory; '.' says so), at most MAX_PATH characters, no NUL, and text that can be printed
    (bytes that are not UTF-8 reach Python as surrogates no message can print)."""
    if value is None:
        return None
    if not value.strip():
        fail(f"{option} is empty: give a directory ('.' for the working directory)")
    if len(value) > MAX_PATH or "\0" in value:
        fail(
            f"{option}: not a path ({len(value)} characters{', a NUL' if chr(0) in value else ''};"
            f" at most {MAX_PATH})"
        )
    try:
        value.encode("utf-8")
    except UnicodeEncodeError:
        fail(
            f"{option}: the path {value.encode('utf-8', 'backslashreplace').decode()[:200]} "
            "is not UTF-8 text; rename it or give another"
        )
    return Path(value)


def os_fail(e: OSError, doing: str) -> None:
    from .files import os_error_text

    fail(f"{doing}: {os_error_text(e)}")
