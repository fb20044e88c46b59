"""Trainers never outlive their worker: a parent-death signal where the worker is our parent,
and a thread that polls the watched pid everywhere else (ranks under torchrun have the agent as
their parent, not the worker)."""

from __future__ import annotations

import ctypes
import os
import signal
import sys
import threading
from collections.abc import Callable
from pathlib import Path

_PR_SET_PDEATHSIG = 1
POLL_S = 1.0


def alive(pid: int) -> bool:
    """Whether ``pid`` runs: it exists and (on Linux) is no zombie waiting for its parent."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # someone else's process: it exists
    stat = Path(f"/proc/{pid}/stat")
    try:
        # The state follows the parenthesised command name, which may itself hold spaces.
        return stat.read_text().rpartition(")")[2].split()[0] != "Z"
    except (OSError, IndexError):
        return not sys.platform.startswith("linux")


def watch_pid(pid: int, on_gone: Callable[[], None], poll_s: float = POLL_S) -> threading.Thread:
    """Call ``on_gone`` (from a daemon thread) once ``pid`` no longer runs; the thread is returned."""
    if pid == os.getppid():
        _parent_death_signal()

    def poll() -> None:
        stop = threading.Event()
        while alive(pid):
            stop.wait(poll_s)
        on_gone()

    thread = threading.Thread(target=poll, name=f"watch-pid-{pid}", daemon=True)
    thread.start()
    return thread


def _parent_death_signal() -> None:
    """Ask Linux to SIGKILL us when our parent dies (nothing elsewhere: the poll covers it)."""
    if not sys.platform.startswith("linux"):
        return
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    except (OSError, AttributeError):
        return
