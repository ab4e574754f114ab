"""Read the rig's TXT runs and convert them to SI units and our sign conventions.

>>> from grip_force_ros.lab.rig import read_run, to_contract_log      # doctest: +SKIP
>>> run = read_run('Tool_4_Maryland_L_2/11.TXT')                  # doctest: +SKIP
>>> run.frequency_hz, run.torque_level_percent                    # doctest: +SKIP
(0.2, 20.0)
>>> log = to_contract_log(run)       # docs/design.md CSV contract + extra columns

One place normalises the raw file (:func:`read_run`); everything downstream
sees SI values, closing-positive signs, and named fields.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from grip_force_ros.lab.rig import constants as C


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
        Commanded input-disk angle (rad), positive closing (the file holds rad in
        ``Tool_4_Maryland_L_2`` and disk-encoder counts in later folders: both read).
    yaw_step : int or None
        Z of a ``ZXY.TXT`` name (jaw stopping position of the roll/pitch/yaw folders),
        None for ``XY.TXT``.
    spindle : str
        ``'left'`` or ``'right'``: the instrument input spindle the back end drives.
    spindle_source : str
        Where ``spindle`` comes from: ``'header'`` (the ``Used left spindle`` line),
        ``'folder'`` (``_L_``/``_R_`` in the folder name) or ``'default'`` (neither: left).
    file : str
        File name as on disk, e.g. ``'11.TXT'``.
    folder : str
        Name of the folder holding the file.
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
    yaw_step: int | None = None
    spindle: str = 'left'
    spindle_source: str = 'default'
    file: str = ''
    folder: str = ''

    def __len__(self) -> int:
        return int(self.t.size)


#: ``XY.TXT`` or ``ZXY.TXT`` (upstream README): X frequency, Y resisting torque, Z yaw.
_NAME = re.compile(r'^(\d)?(\d)(\d)\.txt$', re.IGNORECASE)
_FREQ = re.compile(r'([0-9.]+)\s*Hz', re.IGNORECASE)
_TORQUE = re.compile(r'reaction torque of\s*([0-9.]+)\s*percent', re.IGNORECASE)
_SPINDLE = re.compile(r'\b(left|right)\s+spindle', re.IGNORECASE)
_FOLDER_SIDE = re.compile(r'(?:^|_)([LR])(?:_|$)')


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


def spindle_of(header: dict, folder: str) -> tuple[str, str]:
    """Which input spindle a run drives, and where that was read.

    Parameters
    ----------
    header : dict
        Parsed header (:func:`read_run`); its ``description`` says ``Used left
        spindle ...`` or ``Used right spindle ...``.
    folder : str
        Folder name, e.g. ``Tool_4_Maryland_R_5`` (``_L_``/``_R_``).

    Returns
    -------
    (str, str)
        ``('left' | 'right', 'header' | 'folder' | 'default')``.
    """
    match = _SPINDLE.search(header.get('description', ''))
    if match:
        return match.group(1).lower(), 'header'
    match = _FOLDER_SIDE.search(folder)
    if match:
        return ('left' if match.group(1) == 'L' else 'right'), 'folder'
    return 'left', 'default'


def _load_rows(path: Path, skip: int, rows: int | None) -> np.ndarray:
    """Numeric rows of a run file: the fast reader first, a tolerant line parser on failure.

    The tolerant path keeps rows of exactly :data:`.constants.RAW_COLUMNS` finite
    numbers and drops the rest (a truncated last line of an SD-card log, a stray
    text line); it refuses a file where more than 1 % of the lines are dropped.
    """
    ncol = len(C.RAW_COLUMNS)
    try:
        raw = np.loadtxt(path, delimiter=',', comments='%', dtype=np.float64, ndmin=2,
                         skiprows=skip, max_rows=rows, encoding='latin-1')
    except ValueError:
        raw = None
    if raw is not None:
        if raw.shape[1] != ncol:
            raise RigDataError(f'{path}: expected {ncol} columns, got {raw.shape[1]}')
        if np.all(np.isfinite(raw)):
            return raw
    kept, dropped = [], 0
    with open(path, 'r', encoding='latin-1') as fh:
        for line in fh:
            text = line.strip()
            if not text or text.startswith('%'):
                continue
            parts = text.rstrip(',').split(',')
            try:
                values = [float(v) for v in parts]
            except ValueError:
                dropped += 1
                continue
            if len(values) != ncol or not all(np.isfinite(values)):
                dropped += 1
                continue
            kept.append(values)
            if rows is not None and len(kept) >= rows:
                break
    if not kept:
        raise RigDataError(f'{path}: no row of {ncol} numbers')
    if dropped > 0.01 * (len(kept) + dropped):
        raise RigDataError(f'{path}: {dropped} of {len(kept) + dropped} data lines are not '
                           f'{ncol} numbers (expected {ncol} columns)')
    return np.asarray(kept, dtype=np.float64)


def read_run(path, *, rows: int | None = None) -> RigRun:
    """Read one ``XY.TXT`` or ``ZXY.TXT`` run.

    Both upstream formats are read: ``Tool_4_Maryland_L_2`` (values with decimals,
    disk encoder 0 at the start, trajectory in rad) and the later folders
    (integer-like encoder and torque counts, the disk encoder at its index-pulse
    reference, trajectory in disk counts, current with another resolution). A
    right-spindle run (header ``Used right spindle``, or ``_R_`` in the folder
    name) has every raw column negated first, as upstream's own loader does
    (``compileData.m``), so that closing is positive on both spindles.

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
        Unreadable file, a name not of the form ``XY.TXT``/``ZXY.TXT``, a wrong
        column count, or time that does not rise.
    """
    path = Path(path)
    match = _NAME.match(path.name)
    if not match:
        raise RigDataError(f'{path}: expected a run file named XY.TXT or ZXY.TXT (Z = yaw, '
                           f'X = frequency, Y = torque level)')
    try:
        with open(path, 'r', encoding='latin-1') as fh:
            header_lines = []
            for line in fh:
                if line.startswith('%') or not line.strip():
                    header_lines.append(line)
                else:
                    break
        raw = _load_rows(path, len(header_lines), rows)
    except OSError as exc:
        raise RigDataError(f'{path}: cannot read rig file: {exc}') from None
    raw = _monotonic_time(path, raw)
    header = _parse_header(header_lines)
    desc = header.get('description', '')
    freq_match, torque_match = _FREQ.search(desc), _TORQUE.search(desc)
    yaw = int(match.group(1)) if match.group(1) is not None else None
    fx, ty = int(match.group(2)), int(match.group(3))
    frequency = float(freq_match.group(1)) if freq_match else \
        C.FREQUENCY_FIRST_HZ + C.FREQUENCY_STEP_HZ * fx
    level = float(torque_match.group(1)) if torque_match else \
        C.TORQUE_FIRST_PERCENT + C.TORQUE_STEP_PERCENT * ty
    folder = path.resolve().parent.name
    spindle, source = spindle_of(header, folder)
    run = _convert(path.stem, fx, ty, frequency, level, header, raw, spindle)
    return replace(run, yaw_step=yaw, spindle=spindle, spindle_source=source, file=path.name,
                   folder=folder)


def _monotonic_time(path: Path, raw: np.ndarray) -> np.ndarray:
    """Time in s, strictly rising: ms are converted, a few repeated stamps dropped."""
    if raw.shape[0] < 2:
        raise RigDataError(f'{path}: time must rise strictly over at least 2 rows')
    t = raw[:, 0]
    if np.median(np.diff(t)) > 0.5:          # stamps in ms (the upstream header's unit)
        raw = raw.copy()
        raw[:, 0] = t / 1000.0
        t = raw[:, 0]
    keep = np.concatenate([[True], np.diff(t) > 0])
    if not np.all(keep):
        # a stamp that does not rise is dropped with its row; more than 1 % is an error
        running = np.maximum.accumulate(t)
        keep = np.concatenate([[True], t[1:] > running[:-1]])
        if keep.sum() < 0.99 * t.size or keep.sum() < 2:
            raise RigDataError(f'{path}: time must rise strictly over at least 2 rows')
        raw = raw[keep]
    return raw


def _convert(name, fx, ty, frequency, level, header, raw, spindle='left') -> RigRun:
    col = {n: raw[:, i].copy() for i, n in enumerate(C.RAW_COLUMNS)}
    disk_offset = 0.0
    if spindle == 'right':
        # upstream compileData.m: "Flip pretty much everything, since we are doing right jaw"
        for key in col:
            if key != 'time':
                col[key] = -col[key]
        disk_offset = C.RIGHT_SPINDLE_DISK_OFFSET
    disk_counts = col['disk_counts']
    motor_counts = col['motor_counts'] - col['motor_counts'][0]   # not zeroed upstream
    target = col['trajectory_target']
    if np.max(np.abs(target)) > C.TRAJECTORY_COUNTS_ABOVE:
        target = target * (C.TWO_PI / C.DISK_COUNTS_PER_REV)      # later folders: counts
    return RigRun(
        name=name, frequency_step=fx, torque_step=ty, frequency_hz=frequency,
        torque_level_percent=level, header=header,
        t=col['time'] - col['time'][0],
        current=col['measured_current'].copy(),
        current_command=C.BACKEND_COMMAND_SIGN * C.BACKEND_COMMAND_FULL_SCALE * col['backend_command'],
        motor_angle=C.DISK_SIGN * disk_counts * (C.TWO_PI / C.DISK_COUNTS_PER_REV) + disk_offset
        + 0.0,  # no -0.0
        motor_shaft_angle=C.MOTOR_SIGN * motor_counts * (C.TWO_PI / C.MOTOR_COUNTS_PER_OUTPUT_REV),
        jaw_angle=C.JAW_CLOSING_SIGN * (C.JAW_REFERENCE_COUNTS - col['jaw_counts'])
        * (C.TWO_PI / C.JAW_COUNTS_PER_REV),
        jaw_torque=C.JAW_TORQUE_SIGN * C.TORQUE_NM_PER_COUNT * col['jaw_torque_counts'],
        disk_torque=C.DISK_TORQUE_SIGN * C.TORQUE_NM_PER_COUNT * col['disk_torque_counts'],
        load_command=col['load_command'].copy(),
        trajectory_angle=C.DISK_SIGN * target + 0.0,
    )


def run_files(directory) -> list[Path]:
    """List the ``XY.TXT`` / ``ZXY.TXT`` run files of a rig folder, sorted by name.

    Other files (``ReadME.txt``, ``SerialLog.txt``) are skipped.

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
        raise RigDataError(f'{directory}: no XY.TXT run files (nor ZXY.TXT)')
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


def data_root() -> Path:
    """Find the ``mis-tool-characterization`` folder: ``shared/data/...`` beside the repository.

    Looked for beside every parent of the package (a git worktree one level deeper
    finds the same shared copy); the first that exists wins, else the one beside
    the repository root.
    """
    here = Path(__file__).resolve()
    for parent in here.parents:
        candidate = parent.joinpath(*C.DATA_ROOT)
        if candidate.is_dir():
            return candidate
    return here.parents[4].joinpath(*C.DATA_ROOT)


def default_data_dir() -> Path:
    """``../shared/data/mis-tool-characterization/Tool_4_Maryland_L_2`` (see :func:`data_root`)."""
    return data_root() / C.DEFAULT_FOLDER
