"""The trainers' process group: started in a session of its own, stopped whole (no orphans)."""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

from model.runs.launcher import ProcessGroup, device_env, group_members, torchrun_command
from tests.waiting import until

# A leader that starts two grandchildren which ignore SIGTERM, then prints and sleeps: the worst
# case for a cancel (only SIGKILL to the whole group stops them).
TREE = """
import signal, subprocess, sys, time
kids = [subprocess.Popen([sys.executable, "-c",
        "import signal, time; signal.signal(signal.SIGTERM, signal.SIG_IGN); print('child up', flush=True); time.sleep(600)"])
        for _ in range(2)]
print("leader up", flush=True)
time.sleep(600)
"""


def test_stop_kills_the_whole_group_and_leaves_no_process() -> None:
    group = ProcessGroup([sys.executable, "-c", TREE])
    seen: list[str] = []
    # The two children write to one pipe at once, so their lines may interleave: count the bytes.
    until(lambda: seen.extend(group.lines()) or "".join(seen).count("child up") == 2)
    assert "leader up" in seen
    assert group.pgid != os.getpgrp(), "the trainers must not share the worker's process group"
    members = group_members(group.pgid)
    assert len(members) == 3
    started = time.monotonic()
    code = group.stop(grace_s=1.0)
    assert code != 0
    assert time.monotonic() - started < 10
    # The group is gone once its last member is reaped, which a loaded machine may take a moment to do.
    until(lambda: group_members(group.pgid) == [], timeout=5, what="the stopped group to be reaped")
    for pid in members:
        assert not Path(f"/proc/{pid}").exists() or "Z" in (Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2][:3])


def test_output_lines_arrive_and_exit_status_is_kept() -> None:
    group = ProcessGroup([sys.executable, "-c", "print('rank 0 says hi'); raise SystemExit(3)"])
    assert group.wait() == 3
    assert group.lines() == ["rank 0 says hi"]
    assert not group.group_alive()


def test_torchrun_command_single_node_and_multi_node(tmp_path: Path) -> None:
    run_dir = tmp_path / "7"
    single = torchrun_command(run_dir, {"nproc": 2}, watch_pid=123)
    # One machine: torchrun's agent with its rendezvous on loopback (tests/test_trainer_sockets.py).
    assert single[:3] == [sys.executable, "-m", "model.train.agent"]
    assert "--standalone" not in single and single[single.index("--nproc-per-node") + 1] == "2"
    # The ranks watch the worker and their parent (torchrun starts each in a session of its own).
    assert single[-6:] == ["-m", "model.train", str(run_dir), "--watch-pid", "123", "--watch-parent"]
    assert single[single.index("--local-ranks-filter") + 1] == "0"  # rank 0's output is the job log
    paper = torchrun_command(run_dir, {}, watch_pid=1, backbones={"vlm_model_path": "/w/qwen",
                                                                   "mono_model_path": "/w/da"})
    assert paper[paper.index(str(run_dir)) + 1:] == ["--mono-model-path", "/w/da", "--vlm-model-path", "/w/qwen",
                                                     "--watch-pid", "1", "--watch-parent"]
    multi = torchrun_command(run_dir, {"nproc": 4, "nnodes": 2, "rdzv_endpoint": "node0:29400"}, watch_pid=1)
    assert multi[:3] == [sys.executable, "-m", "torch.distributed.run"] and "--standalone" not in multi
    assert multi[multi.index("--rdzv-endpoint") + 1] == "node0:29400"
    assert multi[multi.index("--rdzv-id") + 1] == "run-7"
    assert multi[multi.index("--nnodes") + 1] == "2"


def test_device_env() -> None:
    assert device_env("cpu") == {"CUDA_VISIBLE_DEVICES": ""}
    assert device_env("cuda:0,1") == {"CUDA_VISIBLE_DEVICES": "0,1"}
    assert device_env("auto") == {} and device_env("cuda") == {}
