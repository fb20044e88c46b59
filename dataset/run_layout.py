"""Files of a run directory that the product and the training engine share by name.

Pure (no imports): the engine (``model.train``) reads its names from here, so that a trainer
process loads none of the database layer that ``dataset.services.training`` needs.
"""

RUN_FILE = "run.json"  # RUN_DIR/run.json: the launch spec the ranks read (model.train.spec)
PROGRESS_FILE = "progress.jsonl"  # RUN_DIR/progress.jsonl: the engine's events, mirrored into the job
TENSORBOARD_DIR = "tensorboard"  # RUN_DIR/tensorboard: the SummaryWriter's files
CHECKPOINT_DIR = "checkpoints"  # RUN_DIR/checkpoints: step_XXXXXXX.pt, best.pt, best_step_XXXXXXX.pt
BEST_NAME = "best.pt"
KEEP_FILE = "keep.json"  # RUN_DIR/keep.json: checkpoints the product keeps from rotation
CANCEL_FILE = "cancel"  # RUN_DIR/cancel: the ranks stop after the step that sees it, checkpoint and exit
TRAINERS_FILE = "trainers.json"  # RUN_DIR/trainers.json: the trainer process group the launcher started
LOG_DIR = "logs"  # RUN_DIR/logs: torchrun's per-rank logs
INIT_FILE = "init.json"  # RUN_DIR/init.json: the engine's {"loaded", "fresh", "unused"} keys of an init_stereo start
