"""A run's page, its job, the Jobs list and Compare in a real browser at 1366×768: rank 0's log live
and to download (no server folder in it), run ↔ job linked both ways, what a train job made and
its figures readable, step ticks whole, a warning when compared runs differ in dataset version,
and `?` help on each page."""

from __future__ import annotations

from collections.abc import Iterator
from datetime import timedelta
from pathlib import Path

import pytest

from dataset.db import migrate, transaction
from dataset.services import training
from dataset.services import users as user_service
from dataset.tables import Job, JobState, Role, RunState, TrainingRun, utcnow
from tests.browser import login, page_with_errors, serving
from tests.conftest import PASSWORD, make_settings
from tests.test_run_logs import write_launch
from webapp.runtime import Runtime

pytestmark = [pytest.mark.browser, pytest.mark.slow]
RAW = "61.09056854248047"  # what the pages used to print
STEPS = 12


def _run(s, settings, version: str, state: RunState, job_state: JobState, steps_done: int) -> int:  # type: ignore[no-untyped-def]
    """A run whose engine wrote ``steps_done`` steps and one validation (at step 11, when it got there)."""
    run = TrainingRun(preset="lite", config={"train": {"steps": STEPS}}, dataset_id=version * 64,
                      dataset={"id": version * 64, "items": []}, splits={"train": [1, 2], "val": [3], "test": [4]},
                      state=state, started_at=utcnow())
    s.add(run)
    s.flush()
    events = [{"event": "start", "steps": STEPS, "world_size": 1, "step": 0}]
    events += [{"event": "step", "step": i, "steps": STEPS, "loss": 1 / i, "lr": 2e-4} for i in range(1, steps_done + 1)]
    if steps_done >= 11:
        events.append({"event": "val", "step": 11, "metrics": {"all": {"epe": float(RAW), "bad2": 50.0, "bad3": 40.0}},
                       "images": []})
    training.apply_events(s, run, events)
    job = Job(kind="train", params={"run_id": run.id}, state=job_state, attempts=1, worker="elsewhere:1",
              started_at=utcnow(), heartbeat_at=utcnow() + timedelta(days=1),  # no reaper takes it for lost
              log=f"run {run.id}: trainers in process group 7: {settings.home}/python -m torch.distributed.run\n")
    if job_state == JobState.succeeded:
        job.result = {"run": run.id, "step": STEPS, "checkpoint": None, "best_val_epe": float(RAW)}
        job.progress, job.finished_at, run.finished_at = 1.0, utcnow(), utcnow()
    else:
        job.result = {"run": run.id, "step": steps_done, "steps": STEPS, "loss": 1 / steps_done, "lr": 2e-4,
                      "samples_per_s": 3.14159265, "eta_s": 12.5}
    s.add(job)
    s.flush()
    run.job_id = job.id
    return run.id


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[str, Path, dict[str, int]]]:
    """Users of every role; run 1 succeeded (one validation), run 2 running on another dataset version."""
    settings = make_settings(tmp_path_factory.mktemp("runs-jobs") / "ws")
    migrate(settings.database_url)
    rt = Runtime(settings)
    with transaction(rt.sessions) as s:
        for role in Role:
            user_service.create_user(s, role.value, role, PASSWORD)
        done = _run(s, settings, "a", RunState.succeeded, JobState.succeeded, STEPS)
        live = _run(s, settings, "b", RunState.running, JobState.running, 3)
        jobs = {"done": s.get(TrainingRun, done).job_id, "live": s.get(TrainingRun, live).job_id}
    rt.close()
    run_dir = training.run_dir(settings.runs_dir, live)
    write_launch(run_dir, "run-2_x", "".join(f"step {i}/{STEPS} loss {1 / i:.4f}\n" for i in range(1, 4)),
                 f'  File "{settings.home}/runs/{live}/x.py", line 3\nUserWarning: find_unused_parameters=True\n')
    with serving(settings.home) as url:
        yield url, run_dir, {"done": done, "live": live, **{f"job_{k}": v for k, v in jobs.items()}}


def _help_opens(page) -> None:  # type: ignore[no-untyped-def]
    from playwright.sync_api import expect

    page.locator("body").click(position={"x": 5, "y": 300})
    page.keyboard.press("?")
    expect(page.locator("#keys-help")).to_be_visible()
    page.keyboard.press("Escape")
    expect(page.locator("#keys-help")).to_be_hidden()


def test_a_running_runs_log_grows_links_its_job_and_downloads_whole(browser, server, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    from playwright.sync_api import expect

    url, run_dir, ids = server
    page, errors = page_with_errors(browser)
    login(page, url, "curator", PASSWORD)
    page.goto(f"{url}/models/runs/{ids['live']}")
    log = page.locator("#run-log")
    expect(log).to_contain_text("step 3/12 loss 0.3333")
    expect(log).to_contain_text('File "runs/')
    expect(page.locator("#log-caption")).to_contain_text("of 2 files")
    # the trainer writes on: the page shows it without a reload
    with (run_dir / "logs" / "run-2_x" / "attempt_0" / "0" / "stdout.log").open("a") as out:
        out.write("step 4/12 loss 0.2500\n")
    expect(log).to_contain_text("step 4/12 loss 0.2500", timeout=10_000)
    assert log.evaluate("n => n.scrollTop + n.clientHeight >= n.scrollHeight - 2")  # following the newest line
    home = str(run_dir.parents[1])
    assert home not in page.locator("main").inner_text()

    with page.expect_download() as download:
        page.click("#log-download")
    text = Path(download.value.path()).read_text()
    assert "step 4/12 loss 0.2500" in text and "── 1 of 2: logs/run-2_x/attempt_0/0/stdout.log ──" in text
    assert home not in text and 'File "runs/' in text
    page.screenshot(path=str(tmp_path / "run-log.png"), full_page=True)

    _help_opens(page)
    page.keyboard.press("j")  # the run's job
    page.wait_for_url(f"{url}/jobs/{ids['job_live']}")
    expect(page.locator("#job-made a", has_text=f"run {ids['live']}")).to_have_attribute(
        "href", f"/models/runs/{ids['live']}")
    expect(page.locator("#job-result dd[data-key=samples_per_s]")).to_have_text("3.142")
    expect(page.locator("#job-log")).to_contain_text("trainers in process group 7")
    assert home not in page.locator("main").inner_text()  # nor in the job's log
    _help_opens(page)
    assert errors == []
    page.close()


def test_the_jobs_list_says_what_a_train_job_made_with_readable_numbers(browser, server, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    from playwright.sync_api import expect

    url, _, ids = server
    page, errors = page_with_errors(browser)
    login(page, url, "curator", PASSWORD)
    page.goto(f"{url}/jobs")
    row = page.locator(f"#jobs tbody tr[data-job-id='{ids['job_done']}']")
    expect(row.locator(".outcome")).to_have_text("12 steps · best val EPE 61.09 px")
    expect(row.locator(".made a")).to_have_attribute("href", f"/models/runs/{ids['done']}")
    expect(page.locator(f"#jobs tbody tr[data-job-id='{ids['job_live']}'] .outcome")).to_have_text(
        "step 3/12 · loss 0.3333")
    assert RAW not in page.locator("main").inner_text()
    assert page.evaluate("document.documentElement.scrollWidth") <= 1366
    _help_opens(page)

    row.locator("td:first-child a").click()
    page.wait_for_url(f"{url}/jobs/{ids['job_done']}")
    expect(page.locator("#job-result dd[data-key=best_val_epe]")).to_have_text("61.09")
    assert RAW not in page.locator("main").inner_text()
    page.locator("#job-made a").click()
    page.wait_for_url(f"{url}/models/runs/{ids['done']}")
    expect(page.locator("#run-job")).to_have_attribute("href", f"/jobs/{ids['job_done']}")
    expect(page.locator("#log-caption")).to_have_text("No log: the trainers never started (see the job's log).")
    # one validation point: the step axis reads whole steps, never 10.5
    chart = page.locator("#charts svg[aria-label='validation EPE']")
    expect(chart).to_have_attribute("data-points", "1")
    ticks = chart.locator("text.chart-tick").all_text_contents()
    steps = ticks[-3:]
    assert steps == ["10", "11", "12"], ticks
    assert all("." not in t for t in steps)
    page.screenshot(path=str(tmp_path / "run-done.png"), full_page=True)
    assert errors == []
    page.close()


def test_compare_warns_when_the_runs_were_trained_on_different_data(browser, server, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    from playwright.sync_api import expect

    url, _, ids = server
    page, errors = page_with_errors(browser)
    login(page, url, "curator", PASSWORD)
    page.goto(f"{url}/models/compare?ids={ids['done']},{ids['live']}")
    warning = page.locator("#compare-versions")
    expect(warning).to_be_visible()
    expect(warning).to_contain_text("2 different dataset versions")
    expect(warning).to_contain_text(f"run {ids['done']}: {'a' * 12}")
    versions = page.locator("#compare-table td[data-version]")
    expect(versions).to_have_count(2)
    expect(versions.nth(0)).to_contain_text("a" * 12)
    expect(versions.nth(1)).to_contain_text("b" * 12)
    page.screenshot(path=str(tmp_path / "compare.png"), full_page=True)
    _help_opens(page)
    page.keyboard.press("2")
    page.wait_for_url(f"{url}/models/runs/{ids['live']}")
    # the same run twice is one version: no warning
    page.goto(f"{url}/models/compare?ids={ids['done']},{ids['done']}")
    expect(page.locator("#compare-table td[data-version]").first).to_be_visible()
    expect(warning).to_be_hidden()
    assert errors == []
    page.close()


def test_the_log_is_curators(browser, server) -> None:  # type: ignore[no-untyped-def]
    url, _, ids = server
    page, _ = page_with_errors(browser)
    login(page, url, "annotator", PASSWORD)
    assert page.goto(f"{url}/models/runs/{ids['live']}/log").status == 403
    assert page.goto(f"{url}/models/runs/{ids['live']}/log.txt").status == 403
    page.close()
