"""Training runs and evaluations around the engine: the launch schema (``schema``), starting and stopping
the trainers (``launcher``), the ``train`` and ``evaluate`` job handlers (``handlers``, ``evaluation``),
checkpoints by name (``registry``), an evaluation's report (``report``), and what a launch checks before
it queues (``capacity``: crop and memory; ``start_fit``: the start checkpoint; ``run_length``: how long).

The engine (the network, losses, metrics, ``model.train``, prediction) never imports this package:
``tests/test_layering.py`` keeps it so, and keeps the database layer out of the engine.
"""
