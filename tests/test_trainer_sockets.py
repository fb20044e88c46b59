"""A single-machine run listens on loopback only: while a 2-process CPU run trains, every
listening socket of its processes — the agent's store, gloo's pairs — is on 127.0.0.1 or ::1, even
where the environment points gloo at a network interface. torchrun's own c10d store binds every
interface; the app's launcher must not."""

from __future__ import annotations

import json
import os
import socket
from pathlib import Path

import pytest

from dataset.db import transaction
from dataset.services import training
from model.runs.launcher import TRAINERS_FILE, group_members
from tests.runs_data import add_accepted_samples
from tests.train_runs import events
from tests.waiting import until
from tests.workers import wait_for
from webapp.jobs import runs as run_control

ENDLESS = {"train.steps": 100_000, "train.batch_size": 2, "train.crop": (32, 64), "train.train_iters": 2,
           "train.test_iters": 2, "train.val_every": 100_000, "train.checkpoint_every": 100_000, "train.amp": False}
LOOPBACK = {"127.0.0.1", "::1"}


def socket_inodes(pid: int) -> set[str]:
    """The inodes of the sockets process ``pid`` holds open (``/proc/PID/fd`` → ``socket:[N]``)."""
    found = set()
    try:
        fds = list(Path(f"/proc/{pid}/fd").iterdir())
    except OSError:  # gone meanwhile
        return found
    for fd in fds:
        try:
            target = os.readlink(fd)
        except OSError:
            continue
        if target.startswith("socket:["):
            found.add(target[len("socket:["):-1])
    return found


def listening(pids: list[int]) -> list[tuple[str, int]]:
    """(address, port) of every TCP socket in LISTEN state that one of ``pids`` holds, from
    ``/proc/net/tcp`` and ``/proc/net/tcp6``."""
    inodes = set().union(*(socket_inodes(pid) for pid in pids))
    out = []
    for table, family in (("tcp", socket.AF_INET), ("tcp6", socket.AF_INET6)):
        for line in Path(f"/proc/net/{table}").read_text().splitlines()[1:]:
            fields = line.split()
            if fields[3] != "0A" or fields[9] not in inodes:  # 0A: TCP_LISTEN
                continue
            address, port = fields[1].split(":")
            raw = bytes.fromhex(address)
            # The kernel prints each 32-bit word of the address in host (little-endian) order.
            raw = b"".join(raw[i:i + 4][::-1] for i in range(0, len(raw), 4))
            out.append((socket.inet_ntop(family, raw), int(port, 16)))
    return out


def network_interface() -> str | None:
    """An interface of this machine other than loopback that is up, if any."""
    for name in sorted(os.listdir("/sys/class/net")):
        state = Path(f"/sys/class/net/{name}/operstate")
        if name != "lo" and state.is_file() and state.read_text().strip() == "up":
            return name
    return None


@pytest.mark.slow
@pytest.mark.parametrize("queue_settings", ["sqlite"], indirect=True)
def test_a_two_process_run_listens_on_loopback_only(rt, start_worker, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    interface = network_interface()
    if interface is not None:  # a deployment whose environment points gloo at the network
        monkeypatch.setenv("GLOO_SOCKET_IFNAME", interface)
    start_worker("--queue", "train")
    with transaction(rt.sessions) as s:
        add_accepted_samples(s, rt.media, videos=3)
        run = run_control.launch(rt, s, preset="lite", overrides=ENDLESS, selection=training.DataSelection(),
                                 launch=training.Launch(split=training.parse_split(training.DEFAULT_SPLIT),
                                                        devices="cpu", nproc=2), user=None)
        run_id, job_id, directory = run.id, run.job_id, training.run_dir(rt.settings.runs_dir, run.id)
    until(lambda: events(directory, "step"), 180, "the first step")
    pgid = json.loads((directory / TRAINERS_FILE).read_text())["pgid"]
    members = group_members(pgid)
    sockets = listening(members)
    run_control.cancel(rt, run_id, None)
    wait_for(rt, job_id, lambda j: j.state.finished, 90)
    assert len(members) == 3, members  # the agent and two ranks
    # The agent's store, and each rank's gloo pair listener, at the least.
    assert len(sockets) >= 3, sockets
    assert {address for address, _ in sockets} <= LOOPBACK, sockets
    assert group_members(pgid) == []
