"""The training engine: ``torchrun -m model.train RUN_DIR`` (or ``python -m model.train RUN_DIR``).

Torch-free at import, so the product can read the exit codes without loading torch.
"""

# The run directory's names, shared with the product: re-exported here for the engine's modules.
from dataset.run_layout import BEST_NAME, CANCEL_FILE, CHECKPOINT_DIR, KEEP_FILE  # noqa: F401

EXIT_SUCCEEDED = 0
EXIT_FAILED = 1  # an exception: bad run.json, unreadable data, a crash (the end event says which)
EXIT_USAGE = 2  # bad command line (argparse's own code)
EXIT_DIVERGED = 3  # a non-finite loss or weights; the last good checkpoint stays
EXIT_ORPHANED = 4  # the watched process (--watch-pid) is gone

# A cancelled run exits 0: it stopped as asked, with its checkpoint written, and torchrun reports
# any other status as a crash (with a traceback in the log).
EXIT_CODES = {"succeeded": EXIT_SUCCEEDED, "failed": EXIT_FAILED, "diverged": EXIT_DIVERGED,
              "cancelled": EXIT_SUCCEEDED}

