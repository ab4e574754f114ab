"""Read the rig's TXT runs and convert them to SI units and our sign conventions.

>>> from grip_force_ros.rig import read_run, to_contract_log      # doctest: +SKIP
>>> run = read_run('Tool_4_Maryland_L_2/11.TXT')                  # doctest: +SKIP
>>> run.frequency_hz, run.torque_level_percent                    # doctest: +SKIP
(0.2, 20.0)
>>> log = to_contract_log(run)       # docs/design.md CSV contract + extra columns

One place normalises the raw file (:func:`read_run`); everything downstream
sees SI values, closing-positive signs, and named fields.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from grip_force_ros.rig import constants as C


class RigDataError(ValueError):
    """A rig file cannot be read or does not look like the MRDLab rig format."""


@dataclass(frozen=True)
class RigRun:
    """One rig run in SI units, signs closing-positive (see :mod:`.constants`).

    Attributes
    ----------
    name : str
        File stem, e.g. ``'11'``.
    frequency_step, torque_step : int
        X and Y of the file name ``XY.TXT``.
    frequency_hz : float
        Sine frequency of the disk trajectory (Hz), from the header.
    torque_level_percent : float
        Resisting torque level (% of the front-end motor), from the header.
    header : dict of str to str
        ``key=value`` lines of the header, and ``description``.
    t : ndarray
        Time (s), starting at 0, 1 kHz.
    current : ndarray
        Back-end motor measured current (A), positive closes.
    current_command : ndarray
        Back-end command expressed in A (positive closes), ``-command * 2.05 A``.
    motor_angle : ndarray
        Input-disk (drum) angle (rad) from the disk encoder, positive closing,
        0 at the start of the run (the disk encoder is zeroed there).
    motor_shaft_angle : ndarray
        Gearbox output angle (rad) from the motor encoder (counts / (4196*35)),
        positive closing, 0 at the start of the run.
    jaw_angle : ndarray
        Jaw opening (rad), 0 at the rig's most closed count
        (:data:`.constants.JAW_REFERENCE_COUNTS`), positive open.
    jaw_torque : ndarray
        Jaw torque (N*m) from the front-end torque sensor, positive = closing
        torque the jaw holds against the resisting motor.
    disk_torque : ndarray
        Input-disk torque (N*m) from the back-end torque sensor, positive closing.
    load_command : ndarray
        Front-end (resisting) motor command (A), as recorded.
    trajectory_angle : ndarray
        Commanded input-disk angle (rad), positive closing.
    """

    name: str
    frequency_step: int
    torque_step: int
    frequency_hz: float
    torque_level_percent: float
    header: dict = field(repr=False)
    t: np.ndarray = field(repr=False)
    current: np.ndarray = field(repr=False)
    current_command: np.ndarray = field(repr=False)
    motor_angle: np.ndarray = field(repr=False)
    motor_shaft_angle: np.ndarray = field(repr=False)
    jaw_angle: np.ndarray = field(repr=False)
    jaw_torque: np.ndarray = field(repr=False)
    disk_torque: np.ndarray = field(repr=False)
    load_command: np.ndarray = field(repr=False)
    trajectory_angle: np.ndarray = field(repr=False)

    def __len__(self) -> int:
        return int(self.t.size)


_NAME = re.compile(r'^(\d)(\d)\.txt$', re.IGNORECASE)
_FREQ = re.compile(r'([0-9.]+)\s*Hz', re.IGNORECASE)
_TORQUE = re.compile(r'reaction torque of\s*([0-9.]+)\s*percent', re.IGNORECASE)


def _parse_header(lines: list[str]) -> dict[str, str]:
    header: dict[str, str] = {}
    for line in lines:
        body = line.lstrip('%').strip()
        if '=' in body and not body.startswith('Back-end'):
            key, _, value = body.partition('=')
            header[key.strip()] = value.strip()
        elif body.startswith('Used'):
            header['description'] = body
        elif body.startswith('Back-end'):
            header['columns'] = body
    return header


def read_run(path, *, rows: int | None = None) -> RigRun:
    """Read one ``XY.TXT`` run.

    Parameters
    ----------
    path : str or Path
        The file.
    rows : int, optional
        Read only the first ``rows`` samples (tests, quick looks).

    Returns
    -------
    RigRun

    Raises
    ------
    RigDataError
        Unreadable file, a name not of the form ``XY.TXT``, a wrong column count,
        or non-rising time.
    """
    path = Path(path)
    match = _NAME.match(path.name)
    if not match:
        raise RigDataError(f'{path}: expected a run file named XY.TXT (X = frequency, '
                           f'Y = torque level)')
    try:
        with open(path, 'r', encoding='latin-1') as fh:
            header_lines = []
            for line in fh:
                if line.startswith('%'):
                    header_lines.append(line)
                else:
                    break
        raw = np.loadtxt(path, delimiter=',', comments='%', dtype=np.float64, ndmin=2,
                         skiprows=len(header_lines), max_rows=rows, encoding='latin-1')
    except (OSError, ValueError) as exc:
        raise RigDataError(f'{path}: cannot read rig file: {exc}') from None
    if raw.shape[1] != len(C.RAW_COLUMNS):
        raise RigDataError(f'{path}: expected {len(C.RAW_COLUMNS)} columns, got {raw.shape[1]}')
    if raw.shape[0] < 2 or np.any(np.diff(raw[:, 0]) <= 0):
        raise RigDataError(f'{path}: time must rise strictly over at least 2 rows')
    header = _parse_header(header_lines)
    desc = header.get('description', '')
    freq_match, torque_match = _FREQ.search(desc), _TORQUE.search(desc)
    fx, ty = int(match.group(1)), int(match.group(2))
    frequency = float(freq_match.group(1)) if freq_match else \
        C.FREQUENCY_FIRST_HZ + C.FREQUENCY_STEP_HZ * fx
    level = float(torque_match.group(1)) if torque_match else \
        C.TORQUE_FIRST_PERCENT + C.TORQUE_STEP_PERCENT * ty
    return _convert(path.stem, fx, ty, frequency, level, header, raw)


def _convert(name, fx, ty, frequency, level, header, raw) -> RigRun:
    col = {n: raw[:, i] for i, n in enumerate(C.RAW_COLUMNS)}
    disk_counts = col['disk_counts']
    motor_counts = col['motor_counts'] - col['motor_counts'][0]   # not zeroed upstream
    return RigRun(
        name=name, frequency_step=fx, torque_step=ty, frequency_hz=frequency,
        torque_level_percent=level, header=header,
        t=col['time'] - col['time'][0],
        current=col['measured_current'].copy(),
        current_command=C.BACKEND_COMMAND_SIGN * C.BACKEND_COMMAND_FULL_SCALE * col['backend_command'],
        motor_angle=C.DISK_SIGN * disk_counts * (C.TWO_PI / C.DISK_COUNTS_PER_REV) + 0.0,  # no -0.0
        motor_shaft_angle=C.MOTOR_SIGN * motor_counts * (C.TWO_PI / C.MOTOR_COUNTS_PER_OUTPUT_REV),
        jaw_angle=C.JAW_CLOSING_SIGN * (C.JAW_REFERENCE_COUNTS - col['jaw_counts'])
        * (C.TWO_PI / C.JAW_COUNTS_PER_REV),
        jaw_torque=C.JAW_TORQUE_SIGN * C.TORQUE_NM_PER_COUNT * col['jaw_torque_counts'],
        disk_torque=C.DISK_TORQUE_SIGN * C.TORQUE_NM_PER_COUNT * col['disk_torque_counts'],
        load_command=col['load_command'].copy(),
        trajectory_angle=C.DISK_SIGN * col['trajectory_target'] + 0.0,
    )


def run_files(directory) -> list[Path]:
    """List the ``XY.TXT`` run files of a rig folder, sorted by name.

    Raises
    ------
    RigDataError
        When the folder does not exist or holds no run file.
    """
    directory = Path(directory)
    if not directory.is_dir():
        raise RigDataError(f'{directory}: not a directory')
    files = sorted(p for p in directory.iterdir() if _NAME.match(p.name))
    if not files:
        raise RigDataError(f'{directory}: no XY.TXT run files')
    return files


def read_runs(directory, *, rows: int | None = None) -> list[RigRun]:
    """Read every run of a rig folder (20 x 20k rows take about a second)."""
    return [read_run(p, rows=rows) for p in run_files(directory)]


#: Extra columns written beside the contract columns by :func:`to_contract_log`.
EXTRA_COLUMNS = ('current_command', 'motor_shaft_angle', 'disk_torque', 'load_command',
                 'trajectory_angle')


def to_contract_log(run: RigRun) -> dict[str, np.ndarray]:
    """Convert the run to a log in the docs/design.md CSV contract (``jaw_torque`` variant).

    Columns: ``t`` (s), ``current`` (A), ``motor_angle`` (rad, input disk),
    ``wrist_angle`` (rad, 0: the rig does not move the wrist), ``jaw_angle`` (rad),
    ``jaw_torque`` (N*m), ``object`` (``rigid``: the jaw is coupled to the resisting
    motor), then :data:`EXTRA_COLUMNS`.
    """
    n = len(run)
    log = {
        't': run.t, 'current': run.current, 'motor_angle': run.motor_angle,
        'wrist_angle': np.zeros(n), 'jaw_angle': run.jaw_angle, 'jaw_torque': run.jaw_torque,
        'object': np.full(n, 'rigid'),
    }
    for name in EXTRA_COLUMNS:
        log[name] = getattr(run, name)
    return log


def default_data_dir() -> Path:
    """``../shared/data/mis-tool-characterization/Tool_4_Maryland_L_2`` beside the repository."""
    return Path(__file__).resolve().parents[3].joinpath(*C.DEFAULT_DATA_DIR)
