"""A worker that dies under ``--dist loadfile`` costs one failed test, not a hung run
(tests/crash_safe_scheduling.py): the dead test is not rerun and every other test still runs."""

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


@pytest.mark.parametrize("workers", [1, 2])
def test_a_crashed_worker_costs_one_test(tmp_path: Path, workers: int) -> None:
    for name, text in FILES.items():
        (tmp_path / name).write_text(text)
    # Without the plugin xdist 3.8.0 hangs here with one worker and reruns the crash with two.
    run = subprocess.run([sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-p", "tests.crash_safe_scheduling",
                          "-n", str(workers), "--dist", "loadfile", "-q", "-o", "addopts=", str(tmp_path)],
                         cwd=tmp_path, env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"},
                         capture_output=True, text=True, timeout=120)
    assert "1 failed, 4 passed" in run.stdout, run.stdout + run.stderr
    assert run.stdout.count("node down") == 1, run.stdout  # one crash: the test was not run again


def test_a_segfaulting_worker_says_where_it_died(tmp_path: Path) -> None:
    (tmp_path / "test_segv.py").write_text("import faulthandler\n"
                                            "def test_segfault_here(): faulthandler._sigsegv()\n")
    run = subprocess.run([sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-p", "tests.crash_safe_scheduling",
                          "-n", "1", "--dist", "loadfile", "-q", "-o", "addopts=", str(tmp_path)],
                         cwd=tmp_path, env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"},
                         capture_output=True, text=True, timeout=120)
    assert "1 failed" in run.stdout, run.stdout + run.stderr
    failure = run.stdout.split("FAILURES", 1)[-1]
    assert "Segmentation fault" in failure and "test_segfault_here" in failure, run.stdout
