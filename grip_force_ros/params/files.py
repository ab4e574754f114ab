"""Where the instrument files live: the one owner of the config directory and its names.

Every module that needs an instrument YAML asks here::

    >>> from grip_force_ros.params.files import instrument_path, list_instruments
    >>> instrument_path()                          # doctest: +SKIP
    PosixPath('/.../config/paper_needle_driver.yaml')
    >>> instrument_path('long_jaw_grasper')        # doctest: +SKIP
    >>> [p.stem for p in list_instruments()]       # doctest: +SKIP

The directory is, in this order: the one named by the environment variable
:data:`CONFIG_DIR_ENV` (an override, e.g. for a deployment's own instruments), the
``config/`` folder of a source checkout, the installed ``share/grip_force_ros/config``
(ament_index, after ``colcon build``).
"""
from __future__ import annotations

import os
from pathlib import Path

__all__ = ['CONFIG_DIR_ENV', 'DEFAULT_INSTRUMENT', 'PACKAGE', 'config_dir', 'instrument_path',
           'list_instruments']

#: The ROS package name (its ament share holds ``config/``).
PACKAGE = 'grip_force_ros'
#: Environment variable naming a directory of instrument YAMLs that replaces the shipped one.
CONFIG_DIR_ENV = 'GRIP_FORCE_CONFIG_DIR'
#: The instrument used when none is named: the paper's needle driver (Table 1).
DEFAULT_INSTRUMENT = 'paper_needle_driver'
#: Suffix of an instrument file.
SUFFIX = '.yaml'

#: ``config/`` of a source checkout (two levels above this package's ``params/``).
_SOURCE_CONFIG = Path(__file__).resolve().parents[2] / 'config'


def config_dir() -> Path:
    """Return the directory of the instrument YAMLs.

    Returns
    -------
    Path
        ``$GRIP_FORCE_CONFIG_DIR`` when set; else the source tree's ``config/`` when it
        exists; else the ament share's ``config/``; else the source path (which then
        does not exist, so a lookup names it in its error).
    """
    override = os.environ.get(CONFIG_DIR_ENV)
    if override:
        return Path(override)
    if _SOURCE_CONFIG.is_dir():
        return _SOURCE_CONFIG
    try:
        from ament_index_python.packages import get_package_share_directory
        return Path(get_package_share_directory(PACKAGE)) / 'config'
    except Exception:  # noqa: BLE001 - ament_index absent, or the package not installed with colcon
        return _SOURCE_CONFIG


def instrument_path(name_or_path: str | os.PathLike | None = None,
                    directory: str | os.PathLike | None = None) -> Path:
    """Find an instrument YAML by path, or by name in :func:`config_dir`.

    Parameters
    ----------
    name_or_path : str or path-like, optional
        An existing file (returned as given; ``~`` expanded); or a name with or without
        ``.yaml`` ('long_jaw_grasper'), or a path whose file name is looked up in the
        directory ('config/long_jaw_grasper.yaml' from any directory).
        None (default): :data:`DEFAULT_INSTRUMENT`.
    directory : str or path-like, optional
        Where names are looked up; default :func:`config_dir`. The launch files pass the
        installed ``share/grip_force_ros/config`` (their ``instrument:=`` argument).

    Returns
    -------
    Path

    Raises
    ------
    FileNotFoundError
        Naming what was asked for and where it looked.
    """
    asked = DEFAULT_INSTRUMENT if name_or_path is None else str(name_or_path).strip()
    directory = config_dir() if directory is None else Path(directory)
    p = Path(asked).expanduser()
    if asked and p.is_file():
        return p
    if asked:
        for candidate in (directory / p.name, directory / f'{p.name}{SUFFIX}'):
            if candidate.is_file():
                return candidate
    known = ', '.join(f.stem for f in sorted(directory.glob(f'*{SUFFIX}'))) or 'none'
    raise FileNotFoundError(f'no instrument YAML {asked!r} (looked in {directory}; '
                            f'instruments there: {known}; or give a path to a YAML)')


def list_instruments() -> list[Path]:
    """Every instrument YAML of :func:`config_dir`, sorted by file name."""
    return sorted(config_dir().glob(f'*{SUFFIX}'))
