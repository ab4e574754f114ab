"""Instrument parameter files by name or path (the launch files' ``instrument:=``).

No ROS imports: launch/*.launch.py pass the installed ``share/grip_force_ros/config``;
tests call :func:`instrument_file` directly.
"""
from __future__ import annotations

from pathlib import Path

#: Default ``instrument:=``: the paper's needle driver (config/paper_needle_driver.yaml).
DEFAULT_INSTRUMENT = 'paper_needle_driver.yaml'

def instrument_file(value: str, config_dir: str | Path) -> Path:
    """The parameter YAML that ``instrument:=value`` names.

    Parameters
    ----------
    value : str
        An instrument name, with or without ``.yaml`` (``long_jaw_grasper``): the file of
        that name in ``config_dir``; or a path (anything with a ``/``, or an existing
        file; ``~`` is expanded, relative paths are taken from the current directory).
    config_dir : str or Path
        The installed instrument files: ``share/grip_force_ros/config``.

    Returns
    -------
    Path
        An absolute path to an existing file.

    Raises
    ------
    ValueError
        When the file does not exist; the message lists the installed instruments.
    """
    value = value.strip()
    if not value:
        raise ValueError('instrument:= is empty')
    config_dir = Path(config_dir)
    candidate = Path(value).expanduser()
    if '/' in value or candidate.is_file():
        path = candidate
    else:
        name = value if value.endswith(('.yaml', '.yml')) else value + '.yaml'
        path = config_dir / name
    if not path.is_file():
        known = ', '.join(sorted(p.stem for p in config_dir.glob('*.yaml'))) or 'none'
        raise ValueError(f'instrument:={value}: no such file {path} '
                         f'(installed instruments: {known}; or give a path to a YAML)')
    return path.resolve()
