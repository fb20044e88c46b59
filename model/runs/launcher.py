"""Starting the trainers with torchrun's agent in a process group of their own, and stopping all of them.

On one machine the agent is ``model.train.agent`` (torchrun with a rendezvous on loopback: nothing
of the run listens on the network); across machines it is ``torchrun`` with a c10d rendezvous.
The group (``start_new_session``) holds the agent; it starts each rank in a session of
its own, so "the group" here is the agent's group and every process descending from it, and
stopping it signals each of their groups. The ranks run with ``--watch-parent``: SIGKILL the agent
and the kernel SIGKILLs them too. The engine's ``--watch-pid`` covers the worker: a SIGKILLed
worker cannot signal anyone, so the trainers notice its pid is gone and exit by themselves.

``RUN_DIR/trainers.json`` records the group (its id, its leader's start time and the boot), so a
cancel reaches live trainers even when the job that started them is gone, and never a process that
merely reuses the pid. Ending trainers politely is the engine's ``RUN_DIR/cancel`` flag (they
checkpoint and exit); SIGTERM and SIGKILL to the group come after a grace.
"""

from __future__ import annotations

import contextlib
import json
import os
import queue
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from core.atomic import atomic_write_bytes
from dataset.run_layout import CANCEL_FILE, LOG_DIR, TRAINERS_FILE

PROJECT_ROOT = Path(__file__).resolve().parents[2]
STOP_GRACE_S = 10.0


def torchrun_command(run_dir: Path, launch: dict[str, Any], *, watch_pid: int,
                     backbones: Mapping[str, str] | None = None) -> list[str]:
    """The command line of a run: ``model.train.agent`` (loopback only) on one node, torchrun's
    c10d rendezvous across several. ``backbones``: the frozen backbones' directories on this
    machine by model field (``mono_model_path``, ``vlm_model_path``), passed to the engine.

    Only rank 0's output reaches the console (the job log); every rank's goes to ``RUN_DIR/logs``.
    """
    nnodes = int(launch.get("nnodes") or 1)
    if nnodes > 1 or launch.get("rdzv_endpoint"):
        agent = ["torch.distributed.run", "--nnodes", str(nnodes), "--rdzv-backend", "c10d",
                 "--rdzv-endpoint", str(launch["rdzv_endpoint"]), "--rdzv-id", f"run-{run_dir.name}"]
    else:
        agent = ["model.train.agent"]
    return [sys.executable, "-m", *agent, "--nproc-per-node", str(int(launch.get("nproc") or 1)),
            "--log-dir", str(run_dir / LOG_DIR), "--tee", "3", "--local-ranks-filter", "0",
            "-m", "model.train", str(run_dir), *engine_options(backbones or {}),
            "--watch-pid", str(watch_pid), "--watch-parent"]


def engine_options(backbones: Mapping[str, str]) -> list[str]:
    """``model.train``'s options naming the frozen backbones' directories (``--mono-model-path DIR`` …)."""
    return [option for field, directory in sorted(backbones.items())
            for option in (f"--{field.replace('_', '-')}", directory)]


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
        self.proc.poll()  # reap a leader that already exited, so that it does not count as alive
        stop_group(self.pgid, grace_s)
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


def stop_group(pgid: int, grace_s: float = STOP_GRACE_S) -> None:
    """SIGTERM process group ``pgid`` (torchrun passes it on to its ranks), then SIGKILL every
    group of what is left of it (see :func:`group_members`) after ``grace_s`` seconds. What is left
    includes its processes of before the SIGTERM: a child in a session of its own whose parent the
    SIGTERM ended is reparented out of the tree, and would otherwise live on unseen."""
    before = {pid: start_time(pid) for pid in group_members(pgid)}
    _signal_group(pgid, signal.SIGTERM)
    deadline = time.monotonic() + grace_s
    while time.monotonic() < deadline and _left(pgid, before)[0]:
        time.sleep(0.1)
    left, table = _left(pgid, before)
    for group in {pgid} | {table[pid][1] for pid in left}:
        _signal_group(group, signal.SIGKILL)


def _left(pgid: int, before: dict[int, int | None]) -> tuple[set[int], dict[int, tuple[int, int]]]:
    """The live processes of group ``pgid``, of ``before`` (pid → start time: the same processes, not
    reused pids) and their descendants; with the process table they were read from."""
    table = _processes()
    alive = {pid for pid, started in before.items() if pid in table and start_time(pid) == started}
    return _tree(pgid, table, alive), table


def _signal_group(pgid: int, sig: int) -> None:
    if pgid == os.getpgrp():  # never our own (a child that joined it must not take its caller along)
        return
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(pgid, sig)


def group_members(pgid: int) -> list[int]:
    """Pids of the live (non-zombie) processes of process group ``pgid`` and of every process
    descending from them, whatever its own group (torchrun's ranks lead groups of their own)."""
    return sorted(_tree(pgid, _processes()))


def _processes() -> dict[int, tuple[int, int]]:
    """Every live (non-zombie) process as pid → (parent pid, process group), from Linux ``/proc``."""
    table = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        # Fields after the parenthesised command: state, ppid, pgrp, …
        fields = stat.rpartition(")")[2].split()
        if len(fields) > 2 and fields[0] != "Z":
            table[int(entry.name)] = (int(fields[1]), int(fields[2]))
    return table


def _tree(pgid: int, table: dict[int, tuple[int, int]], roots: Iterable[int] = ()) -> set[int]:
    """The processes of group ``pgid`` and ``roots``, with every descendant, in ``table``."""
    found = {pid for pid, (_, group) in table.items() if group == pgid} | {pid for pid in roots if pid in table}
    grew = True
    while grew:
        children = {pid for pid, (parent, _) in table.items() if parent in found} - found
        found |= children
        grew = bool(children)
    return found


def start_time(pid: int) -> int | None:
    """When ``pid`` started, in clock ticks since boot (``/proc/PID/stat`` field 22); None if gone."""
    try:
        return int((Path("/proc") / str(pid) / "stat").read_text().rpartition(")")[2].split()[19])
    except (OSError, IndexError, ValueError):
        return None


def boot_id() -> str:
    """This boot's id: a start time means nothing across a reboot."""
    try:
        return Path("/proc/sys/kernel/random/boot_id").read_text().strip()
    except OSError:
        return ""


def record_group(run_dir: Path, pgid: int) -> None:
    """Write ``RUN_DIR/trainers.json``: the run's live process group, for whoever must end it."""
    doc = {"pgid": pgid, "start_time": start_time(pgid), "boot_id": boot_id()}
    atomic_write_bytes(run_dir / TRAINERS_FILE, json.dumps(doc).encode())


def recorded_members(run_dir: Path) -> list[int]:
    """The live processes of the group ``trainers.json`` records (see :func:`group_members`); []
    when none lives, when the record is unreadable or from another boot, or when its pid now
    leads another process (reused)."""
    pgid = _recorded_pgid(run_dir)
    return [] if pgid is None else group_members(pgid)


def _recorded_pgid(run_dir: Path) -> int | None:
    # Linux allocates no pid that is still some live group's id, so while a member lives the id
    # is the run's even after its leader has exited; a live leader must be the recorded one.
    try:
        doc = json.loads((run_dir / TRAINERS_FILE).read_text())
        pgid, started, boot = int(doc["pgid"]), doc["start_time"], str(doc["boot_id"])
    except (OSError, ValueError, KeyError, TypeError):
        return None
    if boot != boot_id():
        return None
    now = start_time(pgid)
    return None if now is not None and now != started else pgid


def stop_recorded(run_dir: Path, grace_s: float = STOP_GRACE_S) -> bool:
    """End the recorded group's processes (SIGTERM, then SIGKILL after ``grace_s``); whether any
    lived. The record goes once none is left."""
    pgid = _recorded_pgid(run_dir)
    lived = pgid is not None and bool(group_members(pgid))
    if pgid is not None and lived:
        stop_group(pgid, grace_s)
    if not recorded_members(run_dir):
        forget_group(run_dir)
    return lived


def forget_group(run_dir: Path) -> None:
    (run_dir / TRAINERS_FILE).unlink(missing_ok=True)


def request_stop(run_dir: Path) -> None:
    """Raise the engine's cancel flag: the ranks stop after their current step, checkpoint and exit."""
    atomic_write_bytes(run_dir / CANCEL_FILE, b"cancel\n")


def clear_stop(run_dir: Path) -> None:
    """Lower the cancel flag (a resumed run starts without the last attempt's)."""
    (run_dir / CANCEL_FILE).unlink(missing_ok=True)


# torchrun's failure summary: one entry per failed rank, the root cause (first failure) last.
_FAILURE = re.compile(r"^\s*rank\s*:\s*(\d+).*?\n\s*exitcode\s*:\s*(-?\d+)", re.M)


def death_reason(exit_code: int | None, output: list[str]) -> str | None:
    """How the trainers died when a signal killed them, from the leader's ``exit_code`` and
    torchrun's failure summary in its ``output`` lines: "rank 1 was killed by SIGKILL — out of
    memory?". None when no signal is to blame (a Python error, or a clean exit)."""
    if exit_code is not None and exit_code < 0:
        return _killed("torchrun", -exit_code)
    text = "\n".join(output)
    start = text.rfind("FAILED\n")  # the last summary (a retried attempt prints its own)
    if start < 0:
        return None
    head, _, root = text[start:].partition("Root Cause")
    # The root cause first; after it, other ranks' deaths except the SIGTERM torchrun sent them.
    entries = _FAILURE.findall(root) + _FAILURE.findall(head)
    for i, (rank, code) in enumerate(entries):
        if int(code) < 0 and (i == 0 or -int(code) != signal.SIGTERM):
            return _killed(f"rank {rank}", -int(code))
    return None


def _killed(who: str, signum: int) -> str:
    try:
        name = signal.Signals(signum).name
    except ValueError:
        name = f"signal {signum}"
    # The kernel's OOM killer sends SIGKILL; so does a person, but memory is the common cause.
    return f"{who} was killed by {name}" + (" — out of memory?" if signum == signal.SIGKILL else "")
