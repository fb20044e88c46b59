"""Files of a run directory that the product and the training engine share by name.

Pure (no imports): the engine (``model.train``) reads its names from here, so that a trainer
process loads none of the database layer that ``dataset.services.training`` needs.
"""

INIT_FILE = "init.json"  # RUN_DIR/init.json: the engine's {"loaded", "fresh", "unused"} keys of an init_stereo start
