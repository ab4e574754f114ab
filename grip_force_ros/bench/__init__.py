"""``grip-force bench``: the 1 kHz loop against the middleware floor, model and diagnosis speed.

Parts (each a module; figures are ratios measured side by side in one run,
because the machines are shared and noisy):

* :mod:`.loop`: bare rclpy ping-pong (the floor) and the product's
  sim -> controller -> sim round trip, p50/p99/max, missed periods, CPU per process;
  the child processes are in :mod:`.child`, process handling in :mod:`.procs`;
* :mod:`.model_speed`: vectorised forward/inverse against one ``numpy.exp``, the
  scalar control step as a share of the 1 ms period;
* :mod:`.diagnosis_speed`: diagnosis of a 1 h, 1 kHz log against merely loading it,
  peak memory.

:func:`.run.run_bench` runs them all and returns the JSON structure of
``grip-force bench --json``.
"""
