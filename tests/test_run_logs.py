"""Rank 0's log of a run (its tail and the whole file) with the server's folders hidden, and the
report page's naming of samples and pictures."""

from __future__ import annotations

import os
import re
from pathlib import Path

from dataset.db import transaction
from dataset.services import jobs as job_service
from dataset.services import run_logs, training
from dataset.tables import TrainingRun
from model.runs.report import picture_caption, report_html, sample_label
from tests.test_runs import bearer

ABSOLUTE = re.compile(r"(?<![\w:/.~\]-])/(?:[\w.+@-]+/)+")


def _queued_run(runtime) -> int:  # type: ignore[no-untyped-def]
    """A run row and its train job, as a launch leaves them (no dataset needed here)."""
    with transaction(runtime.sessions) as s:
        run = TrainingRun(preset="lite", config={"train": {"steps": 2}}, dataset_id="ab" * 32)
        s.add(run)
        s.flush()
        run.job_id = job_service.create_job(s, "train", {"run_id": run.id}, None).id
        return run.id


def write_launch(run_dir: Path, name: str, stdout: str, stderr: str = "", ranks: int = 2, started: float = 0.0) -> None:
    """What ``torchrun --log-dir RUN_DIR/logs`` leaves of one launch: every rank's two files."""
    for rank in range(ranks):
        folder = run_dir / "logs" / name / "attempt_0" / str(rank)
        folder.mkdir(parents=True)
        (folder / "stdout.log").write_text(stdout if rank == 0 else f"rank {rank} out\n")
        (folder / "stderr.log").write_text(stderr if rank == 0 else f"rank {rank} err\n")
        if started:
            os.utime(folder, (started, started))


def test_rank0_files_are_every_launch_oldest_first_stdout_before_stderr(tmp_path: Path) -> None:
    run_dir = tmp_path / "runs" / "3"
    write_launch(run_dir, "zz_second", "b\n", started=2_000_000_000)
    write_launch(run_dir, "aa_first", "a\n", "warning\n", started=1_000_000_000)
    (run_dir / "logs" / "aa_first" / "attempt_0" / "0" / "extra.log").write_text("not a log")
    names = [str(p.relative_to(run_dir)) for p in run_logs.rank0_files(run_dir)]
    assert names == ["logs/aa_first/attempt_0/0/stdout.log", "logs/aa_first/attempt_0/0/stderr.log",
                     "logs/zz_second/attempt_0/0/stdout.log", "logs/zz_second/attempt_0/0/stderr.log"]


def test_a_planted_symlink_is_never_read(tmp_path: Path) -> None:
    run_dir = tmp_path / "runs" / "1"
    secret = tmp_path / "secret.txt"
    secret.write_text("password\n")
    folder = run_dir / "logs" / "x" / "attempt_0" / "0"
    folder.mkdir(parents=True)
    (folder / "stdout.log").symlink_to(secret)
    assert run_logs.rank0_files(run_dir) == []


def test_a_log_file_is_read_from_what_was_opened_not_its_path_again(tmp_path: Path, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    """A log file swapped for a link to an outside file right after it was opened: the tail, the
    whole log and the byte count are still the run's own file's."""
    run_dir = tmp_path / "runs" / "2"
    write_launch(run_dir, "r1", "own out\n", "own err\n")
    secret = tmp_path / "secret.txt"
    secret.write_text("password\n" * 100)
    opened = run_logs.open_contained

    def open_then_swap(folder: Path, relative: str):  # type: ignore[no-untyped-def]
        file = opened(folder, relative)
        link = folder / relative
        link.unlink()
        link.symlink_to(secret)
        return file

    monkeypatch.setattr(run_logs, "open_contained", open_then_swap)
    tail = run_logs.tail(run_dir, 10)
    assert tail["lines"] == ["── 1 of 2: logs/r1/attempt_0/0/stdout.log ──", "own out",
                             "── 2 of 2: logs/r1/attempt_0/0/stderr.log ──", "own err"]
    assert tail["bytes"] == len("own out\nown err\n") and tail["more"] is False
    write_launch(run_dir, "r2", "own out 2\n", "own err 2\n", started=4_000_000_000)
    text = "".join(run_logs.log_lines(run_dir))
    assert "password" not in text and "own out 2\n" in text and "own err 2\n" in text


def test_a_hard_linked_log_file_is_not_listed(tmp_path: Path) -> None:
    run_dir = tmp_path / "runs" / "5"
    write_launch(run_dir, "r1", "own\n", "own\n")
    secret = tmp_path / "secret.txt"
    secret.write_text("password\n")
    stdout = run_dir / "logs" / "r1" / "attempt_0" / "0" / "stdout.log"
    stdout.unlink()
    os.link(secret, stdout)
    assert [p.name for p in run_logs.rank0_files(run_dir)] == ["stderr.log"]
    assert "password" not in "".join(run_logs.log_lines(run_dir))
    assert "password" not in str(run_logs.tail(run_dir, 100))


def test_tail_keeps_the_last_lines_with_the_file_headers(settings, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    run_dir = training.run_dir(settings.runs_dir, 4)
    write_launch(run_dir, "r1", "".join(f"step {i}\n" for i in range(50)),
                 f'File "{settings.home}/runs/4/x.py", line 1\nRuntimeError: boom\n')
    tail = run_logs.tail(run_dir, 3)
    assert tail["lines"] == ["── 2 of 2: logs/r1/attempt_0/0/stderr.log ──",
                             f'File "{settings.home}/runs/4/x.py", line 1', "RuntimeError: boom"]
    assert tail["more"] is True and len(tail["files"]) == 2
    whole = run_logs.tail(run_dir, 1000)
    assert whole["more"] is False and whole["lines"][0].startswith("── 1 of 2") and "step 49" in whole["lines"]
    assert whole["bytes"] == sum((run_dir / f).stat().st_size for f in whole["files"])


def test_the_log_routes(client, tokens, runtime) -> None:  # type: ignore[no-untyped-def]
    run_id = _queued_run(runtime)
    run_dir = training.run_dir(runtime.settings.runs_dir, run_id)
    url = f"/models/runs/{run_id}/log"
    empty = client.get(url, headers=bearer(tokens, "curator"))
    assert empty.status_code == 200 and empty.json["files"] == [] and empty.json["lines"] == []
    assert client.get(f"{url}.txt", headers=bearer(tokens, "curator")).status_code == 404
    write_launch(run_dir, "r1", f"loading {runtime.settings.media_root}/ab/cd.png\nstep 1/2 loss 0.5\n",
                 f"{Path(os.__file__).parent}/warnings.py:1: UserWarning\n")
    tail = client.get(f"{url}?lines=2", headers=bearer(tokens, "curator")).json
    assert tail["lines"][0] == "── 2 of 2: logs/r1/attempt_0/0/stderr.log ──"
    assert re.fullmatch(r"\[python\]/lib/python3\.\d+/warnings\.py:1: UserWarning", tail["lines"][1]), tail["lines"]
    assert client.get(f"{url}?lines=0", headers=bearer(tokens, "curator")).status_code == 400
    assert client.get(f"{url}?lines=x", headers=bearer(tokens, "curator")).status_code == 400
    assert client.get(url, headers=bearer(tokens, "annotator")).status_code == 403
    assert client.get("/models/runs/999/log", headers=bearer(tokens, "curator")).status_code == 404
    download = client.get(f"{url}.txt", headers=bearer(tokens, "curator"))
    assert download.status_code == 200 and download.mimetype == "text/plain"
    assert f'filename="run{run_id}_rank0.log"' in download.headers["Content-Disposition"]
    text = download.get_data(as_text=True)
    assert "loading media/ab/cd.png\nstep 1/2 loss 0.5\n" in text and "rank 1" not in text
    assert not ABSOLUTE.search(text) and str(runtime.settings.home) not in text, text
    assert client.get(f"{url}.txt", headers=bearer(tokens, "annotator")).status_code == 403


def test_the_run_page_links_its_job_and_its_log(client, tokens, runtime) -> None:  # type: ignore[no-untyped-def]
    run_id = _queued_run(runtime)
    with transaction(runtime.sessions) as s:
        job_id = training.get_run(s, run_id).job_id
    page = client.get(f"/models/runs/{run_id}", headers=bearer(tokens, "curator")).get_data(as_text=True)
    assert f'href="/jobs/{job_id}"' in page and f'data-log="/models/runs/{run_id}/log"' in page
    assert f'href="/models/runs/{run_id}/log.txt"' in page


def _report(names: list[str]) -> dict:  # type: ignore[type-arg]
    regions = {r: {"epe": 1.23456, "bad1": 10.0, "bad2": 5.0, "bad3": 2.0, "bad5": 1.0} for r in
               ("all", "non_illusion", "illusion", "picture", "mirror")}
    rows = [{"sample": n, "regions": regions} for n in names]
    return {"dataset": "test split of /srv/secret/runs/1", "resolution": "full", "samples": len(names), "failed": [],
            "params": {"checkpoint": "/srv/secret/runs/1/checkpoints/best.pt", "align": "lsq"},
            "methods": {"fusion": {"regions": regions, "per_sample": rows}, "sgbm": {"regions": regions, "per_sample": rows}}}


def test_the_standalone_report_names_samples_and_pictures_and_no_server_folder() -> None:
    label = sample_label({"sample_id": 7, "frame_id": 4, "video_name": "synthetic-0000"})
    assert label == "synthetic-0000 · frame #4" and sample_label({"left": "x.png"}) is None
    pictures = {"worst: video_1/frame_000000": [f"pictures/video_1__frame_000000__{k}.png"
                                                for k in ("left", "gt", "fusion", "fusion_error")]}
    page = report_html(_report(["video_1/frame_000000"]), pictures, {"video_1/frame_000000": label})
    assert [picture_caption(p) for p in pictures["worst: video_1/frame_000000"]] == \
        ["left image", "ground truth", "fusion prediction", "fusion error (0–8 px)"]
    assert "<figcaption>fusion error (0–8 px)</figcaption>" in page and "<h3>worst: synthetic-0000 · frame #4</h3>" in page
    assert "<td>synthetic-0000 · frame #4</td>" in page and "video_1/frame_000000</td>" not in page
    # one row group per region: the table is as wide as the metrics, however many regions there are
    assert page.count('scope="rowgroup"') == 5 and page.count("<th>bad5</th>") == 1
    assert "/srv/secret" not in page and "…/best.pt" in page
