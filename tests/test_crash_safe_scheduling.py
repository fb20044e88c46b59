"""A worker that dies under ``--dist loadfile`` costs at most one failed test, not a hung run
(tests/crash_safe_scheduling.py): the dead test runs once more on a fresh worker, fails if it kills that
one too, and every other test still runs."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
FILES = {
    "test_a.py": "def test_pass_1(): pass\ndef test_pass_2(): pass\n",
    "test_b.py": "import os\ndef test_crash(): os._exit(1)\ndef test_after(): pass\n",
    "test_c.py": "def test_c(): pass\n",
}


def _run(tmp_path: Path, workers: int) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-p", "tests.crash_safe_scheduling",
                           "-n", str(workers), "--dist", "loadfile", "-q", "-o", "addopts=", str(tmp_path)],
                          cwd=tmp_path, env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"},
                          capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("workers", [1, 2])
def test_a_test_that_always_crashes_costs_one_failure(tmp_path: Path, workers: int) -> None:
    for name, text in FILES.items():
        (tmp_path / name).write_text(text)
    # Without the plugin xdist 3.8.0 hangs here with one worker and reruns the crash with two.
    run = _run(tmp_path, workers)
    assert "1 failed, 4 passed, 1 rerun" in run.stdout, run.stdout + run.stderr
    assert run.stdout.count("node down") == 2, run.stdout  # the first worker and the rerun's; no third try
    if workers == 1:  # what the dead worker had run before, in order (its first file passed whole)
        assert "the worker's files, in the order it ran them: test_a.py, test_b.py" in run.stdout, run.stdout


def test_a_crash_that_does_not_recur_passes_on_the_rerun_and_is_still_reported(tmp_path: Path) -> None:
    (tmp_path / "test_once.py").write_text(
        "import os, pathlib\n"
        "def test_crashes_the_first_time():\n"
        "    marker = pathlib.Path(__file__).with_name('crashed')\n"
        "    if not marker.exists():\n"
        "        marker.touch()\n"
        "        os._exit(1)\n"
        "def test_after(): pass\n")
    run = _run(tmp_path, 1)
    assert "2 passed, 1 rerun" in run.stdout and run.returncode == 0, run.stdout + run.stderr
    assert "worker crash: test_once.py::test_crashes_the_first_time (rerun on a fresh worker)" in run.stdout, run.stdout


def test_a_segfaulting_worker_says_where_it_died(tmp_path: Path) -> None:
    (tmp_path / "test_segv.py").write_text("import faulthandler\n"
                                            "def test_segfault_here(): faulthandler._sigsegv()\n")
    run = _run(tmp_path, 1)
    assert "1 failed" in run.stdout, run.stdout + run.stderr
    failure = run.stdout.split("FAILURES", 1)[-1]
    assert "Segmentation fault" in failure and "test_segfault_here" in failure, run.stdout
