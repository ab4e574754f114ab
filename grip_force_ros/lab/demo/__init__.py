"""The closed-loop demo: orchestration of the ROS processes, recording, figures.

Modules
-------
recorder     rclpy node writing every recorded topic to a rosbag2 (MCAP, rosbags)
             and keeping the latest values for the live view
messages     topic -> type, and plain values out of messages (shared with monitor)
series       read a demo bag back (rosbags) and resample it on one grid
analysis     phases, hold-phase error, steady hold ratio, spread (numpy)
plot         the summary PNG
run          one run end to end (:func:`run_task`)
compare      ``--compare-instruments``: calibrate (:mod:`grip_force_ros.identify`), then four
             conditions on three plants
naive_node   the naive baseline (current proportional to master closing) as a node

Only ``recorder``, ``naive_node``, the ``run``/``compare`` orchestration and
the monitor start or use rclpy; everything else is plain numpy. The node
processes are started through :mod:`grip_force_ros.lab.processes`.
"""
from pathlib import Path

from grip_force_ros.params.files import list_instruments


def comparison_configs() -> list[Path]:
    """List the instruments of ``--compare-instruments``: every shipped YAML but maryland."""
    return [p for p in list_instruments() if 'maryland' not in p.name
            and not p.stem.endswith('_calibrated')]
