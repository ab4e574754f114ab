"""Logs for diagnosis: CSV and rosbag2 (MCAP or sqlite3) in the docs/design.md data contract.

A log is a ``dict[str, numpy.ndarray]`` with one row per sample:

| column | unit | meaning |
|---|---|---|
| ``t`` | s | time, rising |
| ``current`` | A | measured motor current |
| ``motor_angle`` | rad | drum angle |
| ``wrist_angle`` | rad | wrist pitch angle |
| ``jaw_angle`` | rad | jaw opening angle (0 = closed) |
| ``grip_force`` | N | measured grip force, or ``jaw_torque`` (N*m) |
| ``object`` | text, optional | ``needle``, ``tissue``, ``rigid`` or ``free`` |

Other numeric columns (e.g. ``motor_velocity``, ``jaw_velocity``, a commanded
current) are kept as they are.

>>> from grip_force_ros.logs import read_log, write_csv      # doctest: +SKIP
>>> log = read_log('run.mcap')                                # doctest: +SKIP
>>> write_csv('run.csv', log)                                 # doctest: +SKIP

No rclpy here: bags are read and written with ``rosbags``.
"""
from grip_force_ros.logs.columns import (CORE_COLUMNS, MEASURED_COLUMNS, OBJECT_COLUMN,
                                         LogError, measured_column, normalise_log)
from grip_force_ros.logs.csvlog import iter_csv, read_csv, write_csv
from grip_force_ros.logs.bag import read_bag, write_bag, is_bag

__all__ = ['CORE_COLUMNS', 'MEASURED_COLUMNS', 'OBJECT_COLUMN', 'LogError', 'measured_column',
           'normalise_log', 'read_log', 'iter_log', 'read_csv', 'iter_csv', 'write_csv',
           'read_bag', 'write_bag', 'is_bag']


def read_log(path, *, chunk_rows: int = 200_000, progress=None, measured: bool = True) -> dict:
    """Read a log (CSV, or a rosbag2 directory / ``.mcap`` / ``.db3`` file).

    Parameters
    ----------
    path : str or Path
        CSV file, or a rosbag2 bag (directory with ``metadata.yaml``, or its
        storage file).
    chunk_rows : int
        Rows parsed at a time from a CSV (bounds the temporary memory).
    progress : callable, optional
        ``progress(rows_read)`` called after every chunk (e.g. to print on stderr).
    measured : bool
        False: accept a log of inputs only (no measured column), as a prediction needs.

    Returns
    -------
    dict of str to numpy.ndarray
        The contract columns (float64, SI units) plus ``object`` (str) when known.

    Raises
    ------
    LogError
        Missing file or columns, non-rising time, unreadable bag.
    """
    if is_bag(path):
        return read_bag(path, progress=progress, measured=measured)
    return read_csv(path, chunk_rows=chunk_rows, progress=progress, measured=measured)


def iter_log(path, *, chunk_rows: int = 200_000, measured: bool = True):
    """Yield a log in chunks of at most ``chunk_rows`` rows (dicts of arrays).

    CSV logs are streamed from disk, so memory stays bounded by the chunk size;
    bags are aligned first (their topics arrive interleaved) and then yielded in chunks.
    ``measured=False`` accepts a log of inputs only.
    """
    if is_bag(path):
        log = read_bag(path, measured=measured)
        n = len(log['t'])
        for start in range(0, n, chunk_rows):
            yield {k: v[start:start + chunk_rows] for k, v in log.items()}
        return
    yield from iter_csv(path, chunk_rows=chunk_rows, measured=measured)
