"""Test files longest first (a pytest plugin, and the table it reads and writes).

Under ``--dist loadfile`` a worker runs a whole file, and xdist hands the files out by their number of
tests, most first, so the slowest files, few long tests each (the browser ones, the demo workspace's),
were started last: one worker could run a long file alone at the end while the other sat idle.
``tests/crash_safe_scheduling.py`` hands the files out longest first instead (classic LPT scheduling), by
the seconds in ``tests/file_durations.json``: per file, the sum of its tests' setup, call and teardown,
measured on the workers of a real run. A file the table does not know counts as the table's median, so a new file is
neither starved nor forced last.

Refresh the table after adding slow tests or files: ``make test-durations`` (a parallel run with
``--write-file-durations``). The files a run measured replace their entries; entries of files that no
longer exist are dropped; the others are kept, so a partial run only updates what it ran.
"""

from __future__ import annotations

import json
import statistics
from collections import defaultdict
from collections.abc import Iterable, Mapping
from pathlib import Path

import pytest

TABLE = Path("tests") / "file_durations.json"  # relative to the rootdir


def table_path(config: pytest.Config) -> Path:
    return config.rootpath / TABLE


def load_costs(path: Path) -> dict[str, float]:
    """The table's seconds per file; empty (every file the same cost) when there is no table."""
    try:
        return {str(name): float(seconds) for name, seconds in json.loads(path.read_text()).items()}
    except FileNotFoundError:
        return {}


def longest_first(files: Iterable[str], costs: Mapping[str, float]) -> list[str]:
    """``files`` by descending cost; an unknown file costs the table's median; ties keep their order."""
    default = statistics.median(costs.values()) if costs else 0.0
    return sorted(files, key=lambda name: -costs.get(name, default))


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--write-file-durations", action="store_true",
                     help=f"write each file's seconds (setup + call + teardown of its tests) to {TABLE}")


def pytest_configure(config: pytest.Config) -> None:
    # On the controller (or a run without xdist): workers' reports reach it with their durations.
    if config.getoption("write_file_durations") and not hasattr(config, "workerinput"):
        config.pluginmanager.register(_Recorder(config.rootpath), "file-durations-recorder")


class _Recorder:
    def __init__(self, root: Path) -> None:
        self.root = root
        self.path = root / TABLE
        self.seconds: defaultdict[str, float] = defaultdict(float)

    def pytest_runtest_logreport(self, report: pytest.TestReport) -> None:
        self.seconds[report.nodeid.split("::", 1)[0]] += report.duration

    def pytest_sessionfinish(self) -> None:
        if not self.seconds:
            return
        table = {name: seconds for name, seconds in load_costs(self.path).items() if (self.root / name).exists()}
        table.update(self.seconds)
        ordered = {name: round(table[name], 1) for name in longest_first(sorted(table), table)}
        self.path.write_text(json.dumps(ordered, indent=1) + "\n")
