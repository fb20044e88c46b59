"""Test files are handed to the workers longest first, by the table of per-file seconds
(tests/file_durations.py), and ``--write-file-durations`` writes that table from a run."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from tests.file_durations import longest_first

ROOT = Path(__file__).resolve().parent.parent


def _run(tmp_path: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-p", "tests.crash_safe_scheduling",
                           "-n", "2", "--dist", "loadfile", "-q", "-o", "addopts=", *args, "tests"],
                          cwd=tmp_path, env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"},
                          capture_output=True, text=True, timeout=120)


def test_longest_first_orders_by_descending_cost() -> None:
    costs = {"tests/test_a.py": 1.0, "tests/test_b.py": 30.0, "tests/test_c.py": 5.0}
    assert longest_first(["tests/test_a.py", "tests/test_b.py", "tests/test_c.py"], costs) == [
        "tests/test_b.py", "tests/test_c.py", "tests/test_a.py"]


def test_an_unknown_file_costs_the_median_and_ties_keep_their_order() -> None:
    costs = {"a": 1.0, "b": 2.0, "c": 10.0, "d": 20.0}  # median 6
    assert longest_first(["a", "new", "b", "c", "d", "other_new"], costs) == ["d", "c", "new", "other_new", "b", "a"]
    assert longest_first(["x", "y", "z"], {}) == ["x", "y", "z"]  # no table: collection order


def test_files_start_on_the_workers_longest_first(tmp_path: Path) -> None:
    # One test a file, so xdist's own order (most tests first) is collection order, alphabetical: it would
    # start test_a first. The costs are the reverse.
    costs = {f"tests/test_{name}.py": float(cost) for cost, name in enumerate("abcdef", start=1)}
    (tmp_path / "tests").mkdir()
    (tmp_path / "tests" / "file_durations.json").write_text(json.dumps(costs))
    for name in "abcdefg":  # test_g is not in the table: it costs the median, 3.5
        (tmp_path / "tests" / f"test_{name}.py").write_text(
            "import os, pathlib\n"
            "def test_it():\n"
            "    with open(pathlib.Path(__file__).parent.parent / 'started.txt', 'a') as log:\n"
            "        log.write(os.environ['PYTEST_XDIST_WORKER'] + ' ' + pathlib.Path(__file__).stem + '\\n')\n")
    run = _run(tmp_path)
    assert "7 passed" in run.stdout, run.stdout + run.stderr
    started: dict[str, list[str]] = {}
    for line in (tmp_path / "started.txt").read_text().splitlines():
        worker, name = line.split()
        started.setdefault(worker, []).append(name.removeprefix("test_"))
    assert len(started) == 2, started
    order = "fedgcba"
    assert {files[0] for files in started.values()} == {"f", "e"}, started  # the two longest start first
    for files in started.values():  # and each worker gets the rest in descending cost
        assert files == sorted(files, key=order.index), started


def test_a_run_writes_the_table_of_seconds_per_file(tmp_path: Path) -> None:
    (tmp_path / "tests").mkdir()
    (tmp_path / "tests" / "file_durations.json").write_text(json.dumps(
        {"tests/test_gone.py": 50.0, "tests/test_fast.py": 99.0, "tests/test_kept.py": 7.0}))
    (tmp_path / "tests" / "test_slow.py").write_text(
        "import time, pytest\n"
        "@pytest.fixture\n"
        "def slow_setup():\n"
        "    time.sleep(0.3)\n"
        "    yield\n"
        "    time.sleep(0.3)\n"
        "def test_one(slow_setup): time.sleep(0.3)\n"
        "def test_two(): time.sleep(0.3)\n")
    (tmp_path / "tests" / "test_fast.py").write_text("def test_fast(): pass\n")
    (tmp_path / "tests" / "test_kept.py").write_text("def test_not_run(): pass\n")
    run = _run(tmp_path, "-p", "tests.file_durations", "--write-file-durations", "-k", "not test_not_run")
    assert "3 passed" in run.stdout, run.stdout + run.stderr
    table = json.loads((tmp_path / "tests" / "file_durations.json").read_text())
    # Measured files replace their entries (setup + call + teardown), a file not run keeps its entry, a
    # file that no longer exists is dropped; the table lists the longest first.
    assert list(table) == ["tests/test_kept.py", "tests/test_slow.py", "tests/test_fast.py"], table
    assert 1.2 <= table["tests/test_slow.py"] < 5, table
    assert table["tests/test_fast.py"] < 0.5 and table["tests/test_kept.py"] == 7.0, table
