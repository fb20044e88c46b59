"""`illusion-studio demo`: the workspace comes from --data-dir or $ILLUSION_STUDIO_HOME alike, the demo
fills only a workspace it created (its users' passwords are published), and it serves before its
training run ends, then makes the run current and evaluates it."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest

from dataset.settings import load_settings
from tests.browser import free_port, stop
from tests.test_cli import ROOT, cli, one_line_error

MARKER = ".illusion-studio-demo"


def test_the_demo_takes_its_workspace_from_the_environment_too(tmp_path: Path) -> None:
    """`ILLUSION_STUDIO_HOME=X demo` once failed with "data dir …/var/demo does not exist". Without
    serving, the demo builds a complete workspace (one demo build serves every check of this test: a
    build takes half a minute)."""
    home = tmp_path / "from-env"
    result = cli("demo", "--no-serve", "--videos", "2", env={"ILLUSION_STUDIO_HOME": str(home)})
    assert result.returncode == 0, result.stderr
    assert (home / MARKER).is_file()
    users = cli("users", "list", env={"ILLUSION_STUDIO_HOME": str(home)}).stdout
    assert all(role in users for role in ("annotator", "curator", "admin"))
    # the logins come last, framed
    tail = result.stdout.strip().splitlines()[-8:]
    assert tail[-1].startswith("└") and any("admin-demo" in line for line in tail)
    _a_complete_workspace(home, result)
    _mirrors_are_mirrors(home, tmp_path)


def _a_complete_workspace(home: Path, result: subprocess.CompletedProcess[str]) -> None:
    """What `demo --no-serve --videos 2` (its output ``result``) left in ``home``, and that a second
    `demo --no-serve` of the same workspace, by --data-dir this time, has nothing to do."""
    for role in ("annotator", "curator", "admin"):
        assert f"{role}-demo" in result.stdout
    # an ingest and a prefilter job per video, then a generation job per annotated frame and one propose
    # job for the approved frames left to annotate
    assert "4 of 4 jobs succeeded" in result.stdout and "7 of 7 jobs succeeded" in result.stdout
    frames = json.loads(cli("--data-dir", str(home), "frames", "list", "--json").stdout)
    states = [f["state"] for f in frames]
    assert len(frames) == 28
    # two videos are too few for a run's splits, so the demo leaves its samples for a curator
    assert states.count("generated") == 6 and states.count("approved") == 6 and states.count("prefiltered") == 12
    assert states.count("rejected") == 4  # each video's captioned and blurred frames, by the heuristic prefilter
    # two videos cannot fill train, val and test (no video in two splits): no run, and the reason
    assert "no demo training run" in result.stderr and "2 video(s)" in result.stderr
    again = cli("--data-dir", str(home), "demo", "--no-serve", "--videos", "2")
    assert again.returncode == 0 and "jobs succeeded" not in again.stdout  # nothing to do twice


def _mirrors_are_mirrors(home: Path, tmp_path: Path) -> None:
    """The demo's ready-made samples type each pair as its scene says (a picture and a mirror), so a
    mirror reaches the COCO file, the authors' layout and an evaluation report."""
    env = {"ILLUSION_STUDIO_HOME": str(home)}
    assert cli("worker", "--burst", env=env).returncode == 0  # generates the annotated frames (no training)
    for layout in ("native", "authors"):
        done = cli("export", str(tmp_path / layout), "--format", layout, "--state", "generated", "--state", "accepted",
                   "--here", env=env)
        assert done.returncode == 0, done.stderr
    coco = [json.loads(f.read_text()) for f in (tmp_path / "native" / "annotations").glob("*.json")]
    categories = {c["name"]: c["id"] for split in coco for c in split["categories"]}
    used = {a["category_id"] for split in coco for a in split["annotations"]}
    assert categories.get("mirror/illusion") in used and categories.get("picture/illusion") in used, categories
    assert any((tmp_path / "authors").rglob("*mirror*")), "the authors' layout has no mirror"
    report = cli("evaluate", "--data", str(tmp_path / "native"), "--format", "native", "--method", "sgbm",
                 "--out", str(tmp_path / "report"), "--here", "--json", env=env)
    assert report.returncode == 0, report.stderr
    assert "mirror" in json.dumps(json.loads(report.stdout))


def test_the_demo_refuses_a_workspace_it_did_not_create(tmp_path: Path) -> None:
    ws = tmp_path / "ws"
    assert cli("--data-dir", str(ws), "init").returncode == 0
    assert cli("--data-dir", str(ws), "users", "create", "ana", "--role", "admin", "--password-stdin",
               stdin="long-enough\n").returncode == 0
    before = sorted(p.name for p in ws.iterdir())
    for how in (("--data-dir", str(ws)), ()):
        env = {} if how else {"ILLUSION_STUDIO_HOME": str(ws)}
        one_line_error(cli(*how, "demo", "--no-serve", "--videos", "1", env=env), "the demo did not create")
    assert sorted(p.name for p in ws.iterdir()) == before
    assert "annotator" not in cli("--data-dir", str(ws), "users", "list").stdout
    # a new folder whose settings point at a database with users is refused too, and stays unwritten
    fresh = tmp_path / "fresh"
    one_line_error(cli("--data-dir", str(fresh), "demo", "--no-serve", "--videos", "1",
                       env={"ILLUSION_STUDIO_DATABASE_URL": f"sqlite:///{ws / 'illusion-studio.db'}"}),
                   "already has users")
    assert not fresh.exists()


def _answers(url: str) -> bool:
    try:
        with urllib.request.urlopen(url, timeout=2) as response:
            return response.status == 200
    except OSError:
        return False


@pytest.mark.slow
@pytest.mark.timeout(1200)  # a 40-step run and an evaluation, on a loaded 2-core machine
def test_the_demo_serves_first_then_makes_its_run_current_and_evaluates_it(tmp_path: Path) -> None:
    pytest.importorskip("torch")
    from dataset.tables import Evaluation, JobState, RunState, TrainingRun
    from webapp.runtime import Runtime

    home, port, log = tmp_path / "demo", free_port(), tmp_path / "demo.log"
    env = {k: v for k, v in os.environ.items() if not k.startswith("ILLUSION_STUDIO_")}
    started = time.monotonic()
    with open(log, "w") as out:
        proc = subprocess.Popen([sys.executable, "-m", "webapp.cli", "--data-dir", str(home), "demo", "--port",
                                 str(port)], cwd=ROOT, env=env, stdout=out, stderr=subprocess.STDOUT, text=True)
    try:
        while not _answers(f"http://127.0.0.1:{port}/login"):
            assert proc.poll() is None, log.read_text()
            assert time.monotonic() - started < 300, log.read_text()
            time.sleep(0.5)
        print(f"first page after {time.monotonic() - started:.0f} s")
        rt = Runtime(load_settings(home))
        with rt.sessions() as s:  # served while the run waits for the train worker or trains
            assert not s.get(TrainingRun, 1).state.finished
        lines = log.read_text().strip().splitlines()  # the logins come last, framed
        assert lines[-1].startswith("└") and "admin-demo" in "".join(lines[-5:]), lines
        deadline = time.monotonic() + 900
        while True:
            assert proc.poll() is None, log.read_text()
            with rt.sessions() as s:
                run, evaluation = s.get(TrainingRun, 1), s.get(Evaluation, 1)
                if evaluation is not None and evaluation.job.state == JobState.succeeded:
                    break
                assert run.state in (RunState.queued, RunState.running, RunState.succeeded), log.read_text()
                assert evaluation is None or evaluation.job.state in (JobState.queued, JobState.running), \
                    log.read_text()
            assert time.monotonic() < deadline, log.read_text()
            time.sleep(2)
        current = json.loads((home / "models" / "current.json").read_text())
        assert current["run"] == 1 and current["step"] in (20, 40)  # the better of its two validations
        assert f"current model: run 1, best checkpoint (step {current['step']} of 40)" in log.read_text()
        with rt.sessions() as s:
            assert s.get(Evaluation, 1).summary, "the Evaluation page has figures"
        rt.close()
    finally:
        stop(proc)
