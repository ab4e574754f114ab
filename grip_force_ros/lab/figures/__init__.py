"""The figure scripts of the docs: each draws one page's figures from the package's code.

One module per figure (``python -m grip_force_ros.lab.figures.<name>``; each prints the
numbers it draws and writes PNGs under ``docs/figures/`` by default):

* :mod:`.model_tables`: docs/model.md, the fitted tables against the exact model;
* :mod:`.control_blackout`: docs/control.md, a watchdog trip in a sensorless grip
  before and after the stick band;
* :mod:`.sim_response`: docs/sim.md, the step response and the loops of every effect.
* :mod:`.ros_graph`: README.md and docs/ros_interface.md, the nodes, topics and services
  (from the topic table in :mod:`grip_force_ros.topics`).

Figures that are a command's output (``grip-force reproduce``, ``demo``, ``tune``,
``realdata``) stay with the command. Drawing goes through :mod:`grip_force_ros.lab.plotting`.
"""
