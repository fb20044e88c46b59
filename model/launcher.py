"""Starting the trainers with ``torchrun`` in a process group of their own, and stopping all of them.

The group (``start_new_session``) is what makes cancel complete: torchrun's agent, its ranks and
anything they spawn share it, so one ``killpg`` reaches every one of them. The engine's
``--watch-pid`` covers the other direction: a SIGKILLed worker cannot signal anyone, so the
trainers notice its pid is gone and exit by themselves.
"""

from __future__ import annotations

import contextlib
import os
import queue
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

PROJECT_ROOT = Path(__file__).resolve().parent.parent
STOP_GRACE_S = 10.0


def torchrun_command(run_dir: Path, launch: dict[str, Any], *, watch_pid: int) -> list[str]:
    """The command line of a run: ``--standalone`` on one node, a c10d rendezvous across several.

    Only rank 0's output reaches the console (the job log); every rank's goes to ``RUN_DIR/logs``.
    """
    nnodes = int(launch.get("nnodes") or 1)
    if nnodes > 1 or launch.get("rdzv_endpoint"):
        rendezvous = ["--nnodes", str(nnodes), "--rdzv-backend", "c10d",
                      "--rdzv-endpoint", str(launch["rdzv_endpoint"]), "--rdzv-id", f"run-{run_dir.name}"]
    else:
        rendezvous = ["--standalone", "--nnodes", "1"]
    return [sys.executable, "-m", "torch.distributed.run", *rendezvous,
            "--nproc-per-node", str(int(launch.get("nproc") or 1)),
            "--log-dir", str(run_dir / "logs"), "--tee", "3", "--local-ranks-filter", "0",
            "-m", "model.train", str(run_dir), "--watch-pid", str(watch_pid)]


def device_env(devices: str) -> dict[str, str]:
    """Environment for the trainers' device choice: which GPUs they see (none for ``cpu``)."""
    if devices == "cpu":
        return {"CUDA_VISIBLE_DEVICES": ""}
    if devices.startswith("cuda:"):
        return {"CUDA_VISIBLE_DEVICES": devices.removeprefix("cuda:")}
    return {}


class ProcessGroup:
    """A command running as the leader of a new process group, its output collected line by line."""

    def __init__(self, command: list[str], *, env_extra: dict[str, str] | None = None,
                 cwd: Path = PROJECT_ROOT) -> None:
        # The trainers inherit the worker's environment; only the device choice and unbuffered
        # output (rank 0's lines reach the job log as they are printed) are added.
        env = {**os.environ, **(env_extra or {}), "PYTHONUNBUFFERED": "1"}
        # cwd first on sys.path for `-m model.train`: the trainers run the worker's own code.
        self.proc = subprocess.Popen(command, cwd=cwd, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, start_new_session=True)
        self.pgid = self.proc.pid
        self._lines: queue.SimpleQueue[str] = queue.SimpleQueue()
        self._reader = threading.Thread(target=self._read, name=f"output-{self.pgid}", daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for raw in self.proc.stdout:
            self._lines.put(raw.decode("utf-8", "replace").rstrip("\n"))

    def lines(self) -> list[str]:
        """The output lines that arrived since the last call (never blocks)."""
        out = []
        while True:
            try:
                out.append(self._lines.get_nowait())
            except queue.Empty:
                return out

    def poll(self) -> int | None:
        return self.proc.poll()

    def stop(self, grace_s: float = STOP_GRACE_S) -> int:
        """SIGTERM the whole group, SIGKILL what is left after ``grace_s``; returns the leader's status."""
        self._signal(signal.SIGTERM)
        deadline = time.monotonic() + grace_s
        while time.monotonic() < deadline and self.group_alive():
            time.sleep(0.1)
        self._signal(signal.SIGKILL)
        return self.wait()

    def wait(self) -> int:
        """Wait for the leader, then for the end of its output (the rest of the group may still hold the pipe)."""
        code = self.proc.wait()
        self._reader.join(timeout=5)
        return code

    def group_alive(self) -> bool:
        """Whether any process of the group is still alive (zombies do not count)."""
        self.proc.poll()  # reaps the leader once it has exited
        return bool(group_members(self.pgid))

    def _signal(self, sig: int) -> None:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(self.pgid, sig)


def group_members(pgid: int) -> list[int]:
    """Pids of the live (non-zombie) processes in process group ``pgid`` (Linux ``/proc``)."""
    members = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        # Fields after the parenthesised command: state, ppid, pgrp, …
        fields = stat.rpartition(")")[2].split()
        if len(fields) > 2 and int(fields[2]) == pgid and fields[0] != "Z":
            members.append(int(entry.name))
    return members
