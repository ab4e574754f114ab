"""The column contract of a diagnosis log, checked in one place."""
from __future__ import annotations

from typing import Mapping

import numpy as np

from grip_force_ros.objects import OBJECTS

#: Columns every log has (SI units: s, A, rad, rad, rad).
CORE_COLUMNS = ('t', 'current', 'motor_angle', 'wrist_angle', 'jaw_angle')
#: The measured column: grip force (N) from a load cell, or jaw torque (N*m) from a rig.
MEASURED_COLUMNS = ('grip_force', 'jaw_torque')
#: Optional text column naming what the jaw holds.
OBJECT_COLUMN = 'object'


class LogError(ValueError):
    """A log cannot be read, or does not follow the data contract."""


def measured_column(log: Mapping[str, np.ndarray]) -> str:
    """Name of the measured column of ``log``: ``'grip_force'`` or ``'jaw_torque'``.

    Raises
    ------
    LogError
        When the log has neither.
    """
    for name in MEASURED_COLUMNS:
        if name in log:
            return name
    raise LogError(f'log has no measured column (one of {", ".join(MEASURED_COLUMNS)}); '
                   f'columns: {", ".join(log)}')


def normalise_log(log: Mapping[str, object], *, where: str = 'log',
                  measured: bool = True) -> dict[str, np.ndarray]:
    """Check a log against the contract and return it as float64/str arrays.

    Numeric columns become contiguous float64 arrays, ``object`` a str array of
    lower-case names. Time must be finite and strictly rising. ``measured=False``
    accepts a log of inputs only (no ``grip_force`` or ``jaw_torque``: what a model
    prediction needs).

    Raises
    ------
    LogError
        Naming the log and what is wrong (missing column, length, time, object name).
    """
    missing = [c for c in CORE_COLUMNS if c not in log]
    if missing:
        raise LogError(f'{where}: missing column(s) {", ".join(missing)} '
                       f'(contract: {", ".join(CORE_COLUMNS)}, grip_force or jaw_torque[, object])')
    if measured:
        measured_column(log)
    out: dict[str, np.ndarray] = {}
    n = None
    for name, values in log.items():
        if name == OBJECT_COLUMN:
            arr = np.char.lower(np.char.strip(np.asarray(values, dtype=str)))
            bad = np.setdiff1d(np.unique(arr), OBJECTS)
            if bad.size:
                raise LogError(f'{where}: unknown object name(s) {", ".join(map(str, bad))} '
                               f'(allowed: {", ".join(OBJECTS)})')
        else:
            try:
                arr = np.ascontiguousarray(values, dtype=np.float64)
            except (TypeError, ValueError) as exc:
                raise LogError(f'{where}: column {name!r} is not numeric: {exc}') from None
        if arr.ndim != 1:
            raise LogError(f'{where}: column {name!r} must be one-dimensional, got shape {arr.shape}')
        if n is None:
            n = arr.size
        elif arr.size != n:
            raise LogError(f'{where}: column {name!r} has {arr.size} rows, expected {n}')
        out[name] = arr
    t = out['t']
    if t.size < 2:
        raise LogError(f'{where}: needs at least 2 samples, got {t.size}')
    if not np.all(np.isfinite(t)):
        raise LogError(f'{where}: time column has non-finite values')
    if np.any(np.diff(t) <= 0):
        i = int(np.argmax(np.diff(t) <= 0))
        raise LogError(f'{where}: time must rise strictly; row {i + 1} has t={t[i + 1]!r} after {t[i]!r}')
    return out
