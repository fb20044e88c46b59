"""pytest-xdist's ``--dist loadfile`` that survives a crashed worker (a pytest plugin).

pytest-xdist 3.8.0, the latest release, hangs the whole run when a worker dies under ``loadfile``: its
``remove_node`` puts every file the dead worker ever had back on the queue, finished ones too, and a
finished file handed to a worker is an empty order that never completes, so nobody is given work again
(pytest-xdist issues #784, #1323, #1378; PR #1371 for the rerun). One CI run sat at 96 % until killed
at 90 minutes after one worker crashed. Here a crash costs at most one failed test and the run goes on:

- only files with tests still to run go back on the queue;
- the test the worker died on runs once more, on a fresh worker, and is reported failed only if it kills
  that one too (so a test that kills its interpreter cannot kill every replacement in turn). A worker
  can die for something an earlier test left behind (one CI run lost a worker to a segfault in the
  garbage collector during a database migration that passes alone); that is worth a clear report, not a
  red run, and the report is clear: every crash, rerun or not, is printed with its stack in the summary;
- a replacement worker starts with two files, as the first workers do, because a worker holds its
  last test until it knows the next one (PR #1328);
- work sent to a worker that died a moment before (the controller has not heard yet) is not an
  INTERNALERROR ending the run: it stays the dead worker's, and goes back on the queue with the rest;
- the failure says why the worker died: each worker's faulthandler writes to a file of its own, and a
  crash report carries that file (the Python stack of every thread at a segfault), where a worker's
  stderr would be lost in a long CI log, and the files the worker had run, in order (a crash in the
  garbage collector is another file's garbage).

It also hands the files out longest first, by the table of ``tests/file_durations.py``, so that the run
does not end on one worker running a long file alone. Remove this module once a pytest-xdist release
carries those fixes (keeping the longest-first order as a ``LoadFileScheduling`` subclass of its own).
"""

from __future__ import annotations

import contextlib
import faulthandler
import shutil
import tempfile
from pathlib import Path
from typing import IO, Any

import pytest
from xdist.scheduler import LoadFileScheduling
from xdist.workermanage import WorkerController

from tests.file_durations import load_costs, longest_first, table_path


class CrashSafeLoadFileScheduling(LoadFileScheduling):
    """``LoadFileScheduling`` whose crash recovery requeues only unfinished files, and reruns the test a
    worker died on once; it hands out the costliest file left first."""

    def __init__(self, config: pytest.Config, log: Any = None) -> None:
        super().__init__(config, log)
        self.costs = load_costs(table_path(config))
        self.crashed_once: set[str] = set()
        self.rerunning: set[str] = set()
        self.history: dict[str, list[str]] = {}  # a crashed test → the files its worker had started, in order

    def remove_node(self, node: WorkerController) -> str | None:
        workload = self.assigned_work.pop(node)
        unfinished = {scope: unit for scope, unit in workload.items() if not all(unit.values())}
        if not unfinished:
            return None
        crashitem = next(nodeid for unit in unfinished.values() for nodeid, done in unit.items() if not done)
        crashed_in = self._split_scope(crashitem)
        self.history[crashitem] = [scope for scope, unit in workload.items() if any(unit.values()) or scope == crashed_in]
        if crashitem in self.crashed_once:
            self.rerunning.discard(crashitem)
            unfinished[crashed_in][crashitem] = True
        else:
            self.crashed_once.add(crashitem)
            self.rerunning.add(crashitem)
        self.workqueue.update({scope: unit for scope, unit in unfinished.items() if not all(unit.values())})
        for other in self.assigned_work:
            self._reschedule(other)
        return crashitem

    def _assign_work_unit(self, node: WorkerController) -> None:
        # xdist pops the queue's first file, at the initial distribution (two files a worker) as later:
        # put the costliest first (a requeued file too).
        if self.workqueue:
            self.workqueue.move_to_end(longest_first(self.workqueue, self.costs)[0], last=False)
        with contextlib.suppress(OSError):  # "cannot send (already closed?)": remove_node requeues the unit
            super()._assign_work_unit(node)

    def schedule(self) -> None:
        replacing = self.collection is not None
        super().schedule()
        if replacing:
            for node in self.nodes:
                self._reschedule(node)


CRASH_LOG = "crash_safe_scheduling_log"
_crash_logs = pytest.StashKey[Path]()
_crash_log_file = pytest.StashKey[IO[str]]()
_crashes = pytest.StashKey[list[tuple[str, str]]]()


@pytest.hookimpl(trylast=True)  # after pytest's own faulthandler plugin, whose stderr target this replaces
def pytest_configure(config: pytest.Config) -> None:
    log = getattr(config, "workerinput", {}).get(CRASH_LOG)
    if log is not None:  # a worker: its fatal errors go to the file the controller reads
        config.stash[_crash_log_file] = stream = open(log, "w")  # noqa: SIM115 - open until the process ends
        faulthandler.enable(stream, all_threads=True)


def pytest_unconfigure(config: pytest.Config) -> None:
    if _crash_logs in config.stash:
        shutil.rmtree(config.stash[_crash_logs], ignore_errors=True)


@pytest.hookimpl(optionalhook=True)
def pytest_configure_node(node: WorkerController) -> None:
    if _crash_logs not in node.config.stash:
        node.config.stash[_crash_logs] = Path(tempfile.mkdtemp(prefix="pytest-crash-logs-"))
    node.workerinput[CRASH_LOG] = str(node.config.stash[_crash_logs] / f"{node.gateway.id}-{id(node)}.log")


@pytest.hookimpl(optionalhook=True)
def pytest_handlecrashitem(crashitem: str, report: pytest.TestReport, sched: Any) -> None:
    """Add what the dead worker's faulthandler wrote (empty when it exited without a fatal error); a test
    that goes to a fresh worker is reported ``rerun``, not failed."""
    node = getattr(report, "node", None)
    ran = getattr(sched, "history", {}).get(crashitem)
    if ran:  # before the stack, which a CI log may cut short
        report.longrepr = f"{report.longrepr}\nthe worker's files, in the order it ran them: {', '.join(ran)}"
    log = getattr(node, "workerinput", {}).get(CRASH_LOG)
    with contextlib.suppress(OSError):
        text = Path(log).read_text(errors="replace").strip() if log else ""
        if text:
            report.longrepr = f"{report.longrepr}\n{text}"
    rerun = crashitem in getattr(sched, "rerunning", ())
    if rerun:
        report.outcome = "rerun"  # type: ignore[assignment] - xdist's documented way (its hook's docstring)
    config = node.config if node is not None else None
    if config is not None:
        config.stash.setdefault(_crashes, []).append(
            (f"{crashitem} ({'rerun on a fresh worker' if rerun else 'failed'})", str(report.longrepr)))


def pytest_report_teststatus(report: pytest.TestReport) -> tuple[str, str, tuple[str, dict[str, bool]]] | None:
    """A rerun crash shows as ``R``, not as the ``F`` of a failure."""
    if report.outcome == "rerun":
        return "rerun", "R", ("RERUN", {"yellow": True})
    return None


def pytest_terminal_summary(terminalreporter: Any, config: pytest.Config) -> None:
    """Every worker crash with its stack, the rerun ones too (a pass on the rerun hides nothing)."""
    for title, text in config.stash.get(_crashes, []):
        terminalreporter.write_sep("=", f"worker crash: {title}")
        terminalreporter.write_line(text)


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log: Any) -> LoadFileScheduling | None:
    """``--dist loadfile`` gets the crash-safe scheduler; every other mode keeps xdist's own."""
    if config.getoption("dist") == "loadfile":
        return CrashSafeLoadFileScheduling(config, log)
    return None
