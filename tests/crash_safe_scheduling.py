"""pytest-xdist's ``--dist loadfile`` that survives a crashed worker (a pytest plugin).

pytest-xdist 3.8.0, the latest release, hangs the whole run when a worker dies under ``loadfile``: its
``remove_node`` puts every file the dead worker ever had back on the queue, finished ones too, and a
finished file handed to a worker is an empty order that never completes, so nobody is given work again
(pytest-xdist issues #784, #1323, #1378; PR #1371 for the rerun). One CI run sat at 96 % until killed
at 90 minutes after one worker crashed. Here a crash costs one failed test and the run goes on:

- only files with tests still to run go back on the queue;
- the test the worker died on is reported failed (xdist does so) and not run again, so a test that
  kills its interpreter cannot kill every replacement in turn;
- a replacement worker starts with two files, as the first workers do, because a worker holds its
  last test until it knows the next one (PR #1328);
- work sent to a worker that died a moment before (the controller has not heard yet) is not an
  INTERNALERROR ending the run: it stays the dead worker's, and goes back on the queue with the rest.

Remove this module once a pytest-xdist release carries those fixes.
"""

from __future__ import annotations

import contextlib
from typing import Any

import pytest
from xdist.scheduler import LoadFileScheduling
from xdist.workermanage import WorkerController


class CrashSafeLoadFileScheduling(LoadFileScheduling):
    """``LoadFileScheduling`` whose crash recovery requeues only unfinished files, once."""

    def remove_node(self, node: WorkerController) -> str | None:
        workload = self.assigned_work.pop(node)
        unfinished = {scope: unit for scope, unit in workload.items() if not all(unit.values())}
        if not unfinished:
            return None
        crashitem = next(nodeid for unit in unfinished.values() for nodeid, done in unit.items() if not done)
        unfinished[self._split_scope(crashitem)][crashitem] = True
        self.workqueue.update({scope: unit for scope, unit in unfinished.items() if not all(unit.values())})
        for other in self.assigned_work:
            self._reschedule(other)
        return crashitem

    def _assign_work_unit(self, node: WorkerController) -> None:
        with contextlib.suppress(OSError):  # "cannot send (already closed?)": remove_node requeues the unit
            super()._assign_work_unit(node)

    def schedule(self) -> None:
        replacing = self.collection is not None
        super().schedule()
        if replacing:
            for node in self.nodes:
                self._reschedule(node)


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log: Any) -> LoadFileScheduling | None:
    """``--dist loadfile`` gets the crash-safe scheduler; every other mode keeps xdist's own."""
    if config.getoption("dist") == "loadfile":
        return CrashSafeLoadFileScheduling(config, log)
    return None
