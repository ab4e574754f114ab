"""The laboratory: everything around the product that a robot does not ship.

The demo, the fault catalogue and check, the benchmarks, the sim-to-real diagnosis, the
da Vinci rig data, the paper's reproduction, the docs' figures, the ``grip-force``
command (``cli``), headless plotting, the offline closed loop (``closed_loop``), and the
process harness that starts nodes as child processes (``processes``) or runs them in
this process (``harness``). The laboratory imports the product (``grip_force_ros.params``,
``model``, ``control``, ``sim``, ``nodes``, ...); the product never imports the laboratory
(test/test_layers.py).
"""
