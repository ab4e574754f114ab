"""Benchmarks: every speed figure of the package, one module per thing measured.

``grip-force bench`` (figures as ratios measured side by side in one run, because
the machines are shared and noisy; :func:`.run.run_bench` returns its JSON):

* :mod:`.loop`: bare rclpy ping-pong (the floor) and the product's
  sim -> controller -> sim round trip, p50/p99/max, missed periods, CPU per process;
  the child processes are in :mod:`.child` and :mod:`.product_sim`, their handling
  in :mod:`.procs`, the statistics in :mod:`.stats`;
* :mod:`.model_speed`: vectorised forward/inverse against one ``numpy.exp``;
* :mod:`.control_step`: the controller's step as a share of the 1 ms period;
* :mod:`.diagnosis_speed`: diagnosis of a 1 h, 1 kHz log against merely loading it,
  peak memory.

Printed by ``python -m grip_force_ros.lab.bench.<module>`` (figures of the docs):
:mod:`.model_speed` (the scalar fast paths), :mod:`.control_step` (step and
node period, grip and free), :mod:`.sim_step` (the simulated instrument's step),
:mod:`.node_timing` (the controller node's own period and tick),
:mod:`.diagnosis_speed` (the long-log report).
"""
