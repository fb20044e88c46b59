"""Trainers never outlive their worker: the pid watch and the parent-death signal."""

from __future__ import annotations

import subprocess
import sys
import threading
import time

from model.train import EXIT_ORPHANED
from model.train.watch import alive, watch_pid

# A child that watches ``pid`` (its argv[1]) and otherwise sleeps for a minute.
_WATCHER = (
    "import os, sys, time\n"
    "from model.train.watch import watch_pid\n"
    f"watch_pid(int(sys.argv[1]), lambda: os._exit({EXIT_ORPHANED}), poll_s=0.2)\n"
    "print('watching', flush=True)\n"
    "time.sleep(60)\n"
)


def test_alive_sees_running_dead_and_zombie_processes() -> None:
    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        assert alive(proc.pid)
        proc.kill()
        deadline = time.monotonic() + 5
        while alive(proc.pid) and time.monotonic() < deadline:  # a zombie until reaped: not alive
            time.sleep(0.05)
        assert not alive(proc.pid)
    finally:
        proc.kill()
        proc.wait()
    assert not alive(proc.pid)


def test_watch_calls_back_once_the_process_is_gone() -> None:
    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    gone = threading.Event()
    watch_pid(proc.pid, gone.set, poll_s=0.05)
    assert not gone.wait(0.3)
    proc.kill()
    proc.wait()
    assert gone.wait(5)


def test_a_watcher_exits_when_the_watched_process_is_killed() -> None:
    worker = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    watcher = subprocess.Popen([sys.executable, "-c", _WATCHER, str(worker.pid)], stdout=subprocess.PIPE, text=True)
    try:
        assert watcher.stdout is not None and watcher.stdout.readline().strip() == "watching"
        worker.kill()
        worker.wait()
        started = time.monotonic()
        assert watcher.wait(timeout=10) == EXIT_ORPHANED
        assert time.monotonic() - started < 5
    finally:
        for proc in (worker, watcher):
            proc.kill()
            proc.wait()


def test_a_child_of_the_watched_process_dies_with_it() -> None:
    # The watched process is the watcher's parent: the parent-death signal stops it at once.
    parent = subprocess.Popen(
        [sys.executable, "-c",
         "import subprocess, sys, time, os\n"
         f"child = subprocess.Popen([sys.executable, '-c', {_WATCHER!r}, str(os.getpid())])\n"
         "print(child.pid, flush=True)\n"
         "time.sleep(60)\n"],
        stdout=subprocess.PIPE, text=True)
    assert parent.stdout is not None
    child_pid = int(parent.stdout.readline())
    time.sleep(0.5)
    assert alive(child_pid)
    parent.kill()
    parent.wait()
    deadline = time.monotonic() + 5
    while alive(child_pid) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not alive(child_pid)
