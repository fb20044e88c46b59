"""``torchrun [--nproc-per-node N] -m model.train RUN_DIR [--watch-pid PID]``, or without torchrun
``python -m model.train RUN_DIR`` (one process). Exit codes: see ``model/train/__init__.py``.
(The app starts a single-machine run with ``python -m model.train.agent``: torchrun on loopback.)

``--mono-model-path DIR`` / ``--vlm-model-path DIR``: where this machine keeps the frozen
backbones (the train worker's settings ``depth_model_path`` / ``vlm_model_path``): the run's
config names none, so that no server path reaches the database.

``--watch-parent``: exit with the parent (torchrun's agent starts each rank in a session of its
own, so a SIGKILLed agent would otherwise leave its ranks running)."""

from __future__ import annotations

import argparse
import os
import sys
import traceback
from dataclasses import replace
from pathlib import Path

from model.train import EXIT_CODES, EXIT_FAILED, EXIT_ORPHANED
from model.train.spec import BACKBONES


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m model.train", description="Train the fusion model of RUN_DIR/run.json.")
    parser.add_argument("run_dir", type=Path, help="The run directory (run.json in it; everything the run writes goes there).")
    parser.add_argument("--watch-pid", type=int, metavar="PID", help="Exit within seconds once this process is gone.")
    parser.add_argument("--watch-parent", action="store_true", help="Exit at once when the parent process is gone.")
    for field, weights, _ in BACKBONES:
        parser.add_argument(f"--{field.replace('_', '-')}", dest=field, metavar="DIR",
                            help=f"The {weights} directory on this machine, in place of run.json's model.{field}.")
    args = parser.parse_args(argv)
    watched = ([args.watch_pid] if args.watch_pid is not None else []) + ([os.getppid()] if args.watch_parent else [])
    if watched:
        from model.train.watch import watch_pid

        for pid in watched:
            # os._exit: the main thread may sit in a collective or a forward pass; nothing else is safe.
            watch_pid(pid, lambda: os._exit(EXIT_ORPHANED))
    if not args.run_dir.is_dir():
        print(f"{args.run_dir}: no such run directory", file=sys.stderr)
        return EXIT_FAILED
    # Heavy imports after the watch starts, so even a trainer still loading torch stops in time.
    from model.train.dist import barrier, close_world, init_world
    from model.train.events import append_event
    from model.train.loop import Trainer
    from model.train.spec import read_run, with_backbones

    world = trainer = None
    try:
        spec = read_run(args.run_dir)
        backbones = {field: path for field, _, _ in BACKBONES if (path := getattr(args, field))}
        spec = replace(spec, config=with_backbones(spec.config, backbones))
        world = init_world(spec.device)
        trainer = Trainer(spec, world)
        outcome = trainer.run()
        # Every rank ends its collectives before any tears the group down: gloo aborts a rank
        # ("terminate called without an active exception") whose peer leaves mid-exchange.
        barrier(world)
        return EXIT_CODES[outcome.state]
    except Exception as exc:  # the run failed: say why in one line, keep the traceback in the log
        traceback.print_exc()
        reason = f"{type(exc).__name__}: {exc}".splitlines()[0]
        # Any rank may fail; the failing one reports (the others are stopped by torchrun).
        append_event(args.run_dir, {"event": "end", "state": "failed", "reason": reason,
                                    "step": None if trainer is None else trainer.step,
                                    "rank": 0 if world is None else world.rank})
        return EXIT_FAILED
    finally:
        if world is not None:
            close_world(world)


if __name__ == "__main__":
    sys.exit(main())
