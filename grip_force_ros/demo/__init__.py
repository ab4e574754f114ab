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
processes are started through :mod:`grip_force_ros.nodes.processes`.
"""
from pathlib import Path

#: Where the instrument YAMLs of a source checkout live.
_SOURCE_CONFIG = Path(__file__).resolve().parents[2] / 'config'


def config_dir() -> Path:
    """The directory of the shipped instrument YAMLs (source tree, else the ament share)."""
    if _SOURCE_CONFIG.is_dir():
        return _SOURCE_CONFIG
    try:
        from ament_index_python.packages import get_package_share_directory
        return Path(get_package_share_directory('grip_force_ros')) / 'config'
    except Exception:  # noqa: BLE001 - not installed with colcon
        return _SOURCE_CONFIG


def find_config(name_or_path: str | Path) -> Path:
    """An instrument YAML by path, or by name in :func:`config_dir` ('paper_needle_driver').

    Raises
    ------
    FileNotFoundError
        Naming where it looked.
    """
    p = Path(name_or_path)
    if p.is_file():
        return p
    for candidate in (config_dir() / p.name, config_dir() / f'{p.name}.yaml'):
        if candidate.is_file():
            return candidate
    raise FileNotFoundError(f'no instrument YAML {name_or_path!r} (looked in {config_dir()})')


def comparison_configs() -> list[Path]:
    """The instruments of ``--compare-instruments``: every shipped YAML except maryland."""
    return sorted(p for p in config_dir().glob('*.yaml') if 'maryland' not in p.name
                  and not p.stem.endswith('_calibrated'))
