"""CSV logs: a header row of column names, then one row per sample (SI units).

Read in chunks with numpy's C parser, so a 1 h log at 1 kHz (3.6 M rows) is
parsed without per-row Python objects and the temporary memory is bounded by the
chunk size.
"""
from __future__ import annotations

import itertools
from pathlib import Path
from typing import Iterator, Mapping

import numpy as np

from grip_force_ros.logs.columns import OBJECT_COLUMN, LogError, normalise_log


def _open_header(path: Path):
    try:
        fh = open(path, 'r', encoding='utf-8', newline='')
    except OSError as exc:
        raise LogError(f'{path}: cannot open log: {exc}') from None
    for line in fh:
        stripped = line.strip()
        if stripped and not stripped.startswith('#'):
            names = [n.strip() for n in stripped.split(',')]
            if len(set(names)) != len(names):
                fh.close()
                raise LogError(f'{path}: duplicate column names in header: {stripped}')
            return fh, names
    fh.close()
    raise LogError(f'{path}: empty CSV (no header row)')


def _parse_chunk(lines: list[str], names: list[str], path: Path, first_row: int) -> dict[str, np.ndarray]:
    numeric = [i for i, n in enumerate(names) if n != OBJECT_COLUMN]
    try:
        values = np.loadtxt(lines, delimiter=',', usecols=numeric, dtype=np.float64, ndmin=2,
                            comments='#')
    except ValueError as exc:
        raise LogError(f'{path}: cannot parse rows from {first_row}: {exc}') from None
    chunk = {names[i]: np.ascontiguousarray(values[:, j]) for j, i in enumerate(numeric)}
    if OBJECT_COLUMN in names:
        k = names.index(OBJECT_COLUMN)
        chunk[OBJECT_COLUMN] = np.loadtxt(lines, delimiter=',', usecols=[k], dtype=str, ndmin=1,
                                          comments='#')
    return chunk


def iter_csv(path, *, chunk_rows: int = 200_000, measured: bool = True) -> Iterator[dict[str, np.ndarray]]:
    """Yield a CSV log as chunks (dicts of arrays) of at most ``chunk_rows`` rows.

    Each chunk is checked against the contract; time must rise across chunks too.
    ``measured=False``: the measured column is optional (a log of inputs only).

    Raises
    ------
    LogError
        Missing file, header or columns; unparsable rows; time not rising.
    """
    path = Path(path)
    fh, names = _open_header(path)
    row = 0
    last_t = -np.inf
    with fh:
        while True:
            lines = [ln for ln in itertools.islice(fh, chunk_rows) if ln.strip()]
            if not lines:
                break
            chunk = _parse_chunk(lines, names, path, row + 1)
            if chunk['t'].size and chunk['t'][0] <= last_t:
                raise LogError(f'{path}: time must rise strictly (row {row + 1}: t={chunk["t"][0]!r} '
                               f'after {last_t!r})')
            if chunk['t'].size >= 2:
                chunk = normalise_log(chunk, where=f'{path} (rows {row + 1}..{row + len(lines)})',
                                      measured=measured)
            else:
                chunk = {k: (v if k == OBJECT_COLUMN else v.astype(np.float64)) for k, v in chunk.items()}
            last_t = chunk['t'][-1]
            row += len(lines)
            yield chunk


def read_csv(path, *, chunk_rows: int = 200_000, progress=None,
             measured: bool = True) -> dict[str, np.ndarray]:
    """Read a whole CSV log into arrays (see :func:`grip_force_ros.logs.read_log`)."""
    parts: dict[str, list[np.ndarray]] = {}
    rows = 0
    for chunk in iter_csv(path, chunk_rows=chunk_rows, measured=measured):
        for k, v in chunk.items():
            parts.setdefault(k, []).append(v)
        rows += len(chunk['t'])
        if progress is not None:
            progress(rows)
    if not parts:
        raise LogError(f'{path}: no data rows')
    log = {}
    for k in list(parts):
        log[k] = np.concatenate(parts.pop(k))
    return normalise_log(log, where=str(path), measured=measured)


def _format_column(values: np.ndarray, name: str) -> np.ndarray:
    if name == OBJECT_COLUMN:
        return np.asarray(values, dtype=str)
    return np.char.mod('%.10g', np.asarray(values, dtype=np.float64))


def write_csv(path, log: Mapping[str, np.ndarray], *, chunk_rows: int = 200_000,
              measured: bool = True) -> Path:
    """Write a log as CSV (header row, then ``%.10g`` values), in chunks.

    Parameters
    ----------
    path : str or Path
        Destination file (parent directories are created).
    log : mapping of str to array
        Columns of the contract (see :mod:`grip_force_ros.logs`); checked first.
    chunk_rows : int
        Rows formatted per chunk (bounds the memory of a long log).
    measured : bool
        False: the log may have no measured column (inputs and model columns only).

    Returns
    -------
    Path
        The file written.
    """
    path = Path(path)
    log = normalise_log(log, where=str(path), measured=measured)
    names = list(log)
    path.parent.mkdir(parents=True, exist_ok=True)
    n = len(log['t'])
    with open(path, 'w', encoding='utf-8', newline='') as fh:
        fh.write(','.join(names) + '\n')
        for start in range(0, n, chunk_rows):
            cols = [_format_column(log[k][start:start + chunk_rows], k) for k in names]
            line = cols[0]
            for col in cols[1:]:
                line = np.char.add(np.char.add(line, ','), col)
            fh.write('\n'.join(line.tolist()))
            fh.write('\n')
    return path
