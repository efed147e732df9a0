"""The rich console the CLIs print tables on."""

from __future__ import annotations

from rich.console import Console


def table_console(piped_width: int = 170):
    """A terminal's own width; piped or captured output (logs, tests) gets `piped_width` columns instead of rich's
    default 80, which would wrap every header and clip name of a wide table."""
    console = Console()
    return console if console.is_terminal else Console(width=piped_width)
