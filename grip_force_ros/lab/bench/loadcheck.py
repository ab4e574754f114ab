"""Run the ROS test files K times under a CPU load and tabulate what failed.

``grip-force loadcheck --runs 20`` (``./dev loadcheck --runs 20``): each run is a fresh
``python -m pytest -m ros test/`` (every test marked ``ros``: real nodes over DDS) in
its own process, its own ROS domain (test/conftest.py), while a
:class:`~grip_force_ros.lab.bench.load.LoadGenerator` keeps every core busy (one busy
process per core by default, started before and stopped after each run; ``--kind disk``
the :class:`~grip_force_ros.lab.bench.pressure.DiskPressure` instead, ``--kind both`` the
two). The junit XML
of each run says which tests failed, erred or skipped and why; the report groups them by
test over the runs. A test that fails in some runs only is a race: its message and the
runs it failed in are what to start from.

Each run also leaves ``run<k>.json``: its outcome and the commit of the checkout it ran,
with a fingerprint of its files but the documentation (so that a commit of docs alone
does not start a new count) and ``dirty`` when the tracked files differed from it. A
series is counted per code:
``grip-force loadcheck --tally FOLDER...`` reads the run files of any number of series
and says, per commit, how many loaded runs were clean (:func:`tally`); a run stopped
midway is incomplete, neither clean nor failed. The bar for a code is 20 clean runs.

No rclpy here: the tests run in child processes.
"""
from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from collections import defaultdict
from pathlib import Path

import psutil

from grip_force_ros.lab.bench.load import LoadGenerator
from grip_force_ros.lab.bench.pressure import make_pressure

#: pytest selection of the ROS tests (the marker of every test that starts real nodes).
ROS_MARKER = 'ros'
#: Longest one run may take before it counts as hung (s).
RUN_TIMEOUT = 1800.0


def test_dir() -> Path:
    """The suite's folder of a source checkout (the tests are not installed).

    Raises
    ------
    FileNotFoundError
        When this package is not run from a source checkout.
    """
    path = Path(__file__).resolve().parents[3] / 'test'
    if not (path / 'conftest.py').is_file():
        raise FileNotFoundError(f'no test suite at {path} (loadcheck needs a source checkout)')
    return path


def _git(path: Path, *args) -> subprocess.CompletedProcess | None:
    try:
        return subprocess.run(['git', '-C', str(path), *args], capture_output=True, text=True,
                              timeout=30)
    except (OSError, subprocess.TimeoutExpired):
        return None


def is_documentation(path: str) -> bool:
    """Tell whether no test runs a file: under ``docs/``, Markdown or reST (CHANGELOG.rst)."""
    return path.startswith('docs/') or path.endswith(('.md', '.rst'))


def code_fingerprint(repo: Path, commit: str) -> str | None:
    """Hash every file of ``commit`` but its documentation (12 hex digits).

    Two commits that differ only in :func:`is_documentation` files run the same code and
    tests: a loaded series counts them as one code. None when ``commit`` is not in ``repo``.
    """
    listing = _git(repo, 'ls-tree', '-r', commit)
    if listing is None or listing.returncode != 0:
        return None
    kept = [line for line in listing.stdout.splitlines()
            if not is_documentation(line.split('\t', 1)[-1])]
    return hashlib.sha1('\n'.join(kept).encode()).hexdigest()[:12]


def source_revision(path: Path) -> dict:
    """Return the checkout's git commit, its code fingerprint and whether it is dirty.

    Returns
    -------
    dict
        ``commit`` (40 hex digits, or None outside a git checkout or without git),
        ``fingerprint`` (:func:`code_fingerprint` of the commit) and ``dirty`` (bool: its
        tracked files other than documentation differ from the commit; None when unknown).
    """
    head = _git(path, 'rev-parse', 'HEAD')
    if head is None or head.returncode != 0:
        return {'commit': None, 'fingerprint': None, 'dirty': None}
    commit = head.stdout.strip()
    status = _git(path, 'status', '--porcelain', '--untracked-files=no')
    dirty = None
    if status is not None and status.returncode == 0:
        dirty = any(not is_documentation(line[3:]) for line in status.stdout.splitlines())
    return {'commit': commit, 'fingerprint': code_fingerprint(path, commit), 'dirty': dirty}


def parse_junit(path: Path) -> dict:
    """Read the tests, failures (with errors) and skips of one junit XML file.

    Returns
    -------
    dict
        ``tests`` (int), ``failed`` and ``skipped``: lists of {'test', 'message'}
        (``test`` = ``file::name`` as pytest prints it, ``message`` the first line).
    """
    root = ET.parse(path).getroot()
    out = {'tests': 0, 'failed': [], 'skipped': []}
    for case in root.iter('testcase'):
        out['tests'] += 1
        name = case.get('classname', '').replace('.', '/') + '.py::' + case.get('name', '')
        for tag, key in (('failure', 'failed'), ('error', 'failed'), ('skipped', 'skipped')):
            node = case.find(tag)
            if node is not None:
                text = (node.get('message') or node.text or '').strip()
                out[key].append({'test': name, 'kind': tag,
                                 'message': text.splitlines()[0][:300] if text else ''})
                break
    return out


#: After SIGINT, how long a stopped run's pytest has to tear its fixtures down (the nodes
#: it started, each in a session of its own) before its session is killed (s).
STOP_GRACE = 15.0


def stop_session(proc: subprocess.Popen) -> None:
    """Stop a pytest run, its session and every process it started: SIGINT, then SIGKILL.

    The tests start their nodes in sessions of their own (``test/_ros_tools.start``), which a
    signal to pytest's session does not reach; its fixtures stop them after SIGINT. A run
    whose pytest does not answer (e.g. deadlocked in rmw, the GIL held) would
    leave them running beside the next runs, so the processes it started, found before the
    signal, are killed with it.
    """
    try:
        started = psutil.Process(proc.pid).children(recursive=True)
    except psutil.NoSuchProcess:
        started = []
    try:
        os.killpg(proc.pid, signal.SIGINT)
        proc.wait(timeout=STOP_GRACE)
    except subprocess.TimeoutExpired:
        pass
    except ProcessLookupError:
        pass
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    for child in started:
        try:
            child.kill()
        except psutil.NoSuchProcess:
            pass


def run_once(index: int, out_dir: Path, workers: int | None = None, duty: float = 1.0,
             select: str = ROS_MARKER, files: list[str] | None = None,
             pytest_args: list[str] | None = None, timeout: float = RUN_TIMEOUT,
             kind: str = 'cpu', disk_options: dict | None = None) -> dict:
    """One pytest run of the selected tests under load; its outcome as a dict.

    Parameters
    ----------
    index : int
        Run number (names the junit and log files).
    out_dir : Path
        Where ``run<index>.xml`` and ``run<index>.log`` go, and ``run<index>.tmp``: the run's
        pytest temporary files (each test's node logs, bags), kept only when the run failed.
    workers, duty
        Of the :class:`LoadGenerator` (default: one busy process per core, full duty);
        ``workers=0`` runs without load (a quiet reference).
    select : str
        pytest ``-m`` expression.
    files : list of str, optional
        Test files or node ids (default: the whole test folder).
    pytest_args : list of str, optional
        Further pytest arguments.
    timeout : float
        Longest run (s); a run that takes longer is killed and counted as failed.
    kind : str
        The load: 'cpu' (the :class:`LoadGenerator`, default), 'disk' (the
        :class:`~grip_force_ros.lab.bench.pressure.DiskPressure`: fsync writers, page-cache
        eviction, optional memory) or 'both'; ``workers=0`` leaves the CPU part out.
    disk_options : dict, optional
        Keywords of the :class:`~grip_force_ros.lab.bench.pressure.DiskPressure`.
    """
    tests = test_dir()
    junit = out_dir / f'run{index}.xml'
    log = out_dir / f'run{index}.log'
    # The run's own temporary files: pytest's numbered ones keep the last three sessions of
    # the user, and any pytest run beside the series (or after it) rotates a failed run's
    # node logs away.
    basetemp = out_dir / f'run{index}.tmp'
    cmd = [sys.executable, '-m', 'pytest', '-q', '-p', 'no:cacheprovider', '-m', select,
           f'--junitxml={junit}', f'--basetemp={basetemp}', *(files or [str(tests)]),
           *(pytest_args or [])]
    env = dict(os.environ)
    env.pop('ROS_DOMAIN_ID', None)     # each run reserves its own (test/conftest.py)
    if workers == 0:        # no CPU part: a quiet reference, or the disk pressure alone
        kind = {'cpu': 'none', 'both': 'disk'}.get(kind, kind)
    load = None
    if kind == 'cpu':
        load = LoadGenerator(workers, seconds=timeout + 60.0, duty=duty)
    elif kind != 'none':
        load = make_pressure(kind, seconds=timeout + 60.0, workers=workers, duty=duty,
                             **(disk_options or {}))
    start = time.monotonic()
    if load is not None:
        load.start()
    loads = []
    try:
        with open(log, 'w') as out:
            # SIGINT at its default, as in a terminal: a runner started in the background
            # (`&`, nohup) would hand the suite SIGINT ignored
            proc = subprocess.Popen(cmd, cwd=tests.parent, env=env, stdout=out,
                                    stderr=subprocess.STDOUT, start_new_session=True,
                                    preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
            try:
                while proc.poll() is None and time.monotonic() - start < timeout:
                    loads.append(os.getloadavg()[0])
                    time.sleep(2.0)
            finally:                    # timed out, or this runner was stopped: the whole run
                if proc.poll() is None:
                    stop_session(proc)
            code = proc.wait()
    finally:
        load_summary = load.stop() if load is not None else {'workers': 0}
    seconds = time.monotonic() - start
    result = {'run': index, 'exit_code': code, 'seconds': round(seconds, 1),
              'timed_out': seconds >= timeout, 'load': load_summary,
              'load_average_mean': round(sum(loads) / len(loads), 2) if loads else None,
              'load_average_max': round(max(loads), 2) if loads else None,
              'junit': str(junit), 'log': str(log)}
    if junit.is_file():
        result.update(parse_junit(junit))
    else:
        result.update(tests=0, failed=[{'test': '(session)', 'kind': 'error',
                                        'message': f'no junit report; exit code {code}'}],
                      skipped=[])
    if result['failed'] or code:
        result['temporary_files'] = str(basetemp)
    else:
        shutil.rmtree(basetemp, ignore_errors=True)
    result['code'] = source_revision(tests.parent)
    result['ended'] = time.strftime('%Y-%m-%dT%H:%M:%S%z')
    (out_dir / f'run{index}.json').write_text(json.dumps(result, indent=1) + '\n')
    return result


def tabulate(runs: list[dict]) -> dict:
    """Group the failures of ``runs`` by test: in how many runs, which, the first message."""
    by_test: dict = defaultdict(lambda: {'runs': [], 'messages': []})
    for r in runs:
        for f in r['failed']:
            entry = by_test[f['test']]
            entry['runs'].append(r['run'])
            entry['messages'].append(f['message'])
    table = {test: {'failed_runs': len(e['runs']), 'runs': e['runs'], 'first_message': e['messages'][0]}
             for test, e in sorted(by_test.items(), key=lambda kv: -len(kv[1]['runs']))}
    skipped: dict = defaultdict(int)
    for r in runs:
        for s in r['skipped']:
            skipped[f"{s['test']}: {s['message']}"] += 1
    return {'runs': len(runs), 'failed_runs': sum(1 for r in runs if r['failed'] or r['exit_code']),
            'failures_by_test': table, 'skips': dict(skipped),
            'seconds': [r['seconds'] for r in runs],
            'load_average_mean': [r['load_average_mean'] for r in runs],
            'tests_per_run': [r['tests'] for r in runs]}


def loadcheck(runs: int, out_dir: Path, progress=None, **run_options) -> dict:
    """Run :func:`run_once` ``runs`` times; the table of :func:`tabulate` plus every run."""
    out_dir.mkdir(parents=True, exist_ok=True)
    results = []
    for k in range(1, runs + 1):
        r = run_once(k, out_dir, **run_options)
        results.append(r)
        if progress is not None:
            progress(r)
    report = tabulate(results)
    report['details'] = results
    report['out_dir'] = str(out_dir)
    return report


_RUN_FILE = re.compile(r'run(\d+)\.(xml|json)')


def read_series(folder: Path) -> list[dict]:
    """Read the runs of one loadcheck folder, in run order.

    A run is there with its record (``run<k>.json``, written when the run ends; the only file
    of a run killed at its timeout, which leaves no junit file), its junit file, or both.
    ``recorded`` says whether it has a record. A junit file without one is of an older
    loadcheck, which wrote none (the record's fields are then None), or of a run whose
    loadcheck was stopped midway.
    """
    folder = Path(folder)
    indices = sorted({int(m.group(1)) for path in folder.iterdir()
                      if (m := _RUN_FILE.fullmatch(path.name))})
    runs = []
    for index in indices:
        record, junit = folder / f'run{index}.json', folder / f'run{index}.xml'
        if record.is_file():
            run = {**json.loads(record.read_text()), 'recorded': True}
        else:
            suite = ET.parse(junit).getroot().find('testsuite')
            run = {'run': index, 'exit_code': None, 'load_average_mean': None,
                   'code': {'commit': None, 'dirty': None}, 'recorded': False,
                   'seconds': float(suite.get('time')) if suite is not None else None,
                   **parse_junit(junit)}
        run['folder'] = str(folder)
        runs.append(run)
    return runs


#: pytest's exit code of a session stopped by SIGINT (its junit file holds the tests done).
INTERRUPTED = 2


def run_status(run: dict, most_tests: int, folder_recorded: bool = False) -> str:
    """Judge one run of a series: ``clean``, ``failed`` or ``incomplete`` (stopped midway).

    ``most_tests``: the largest test count of the run's folder; ``folder_recorded``: whether
    any run of the folder has a record. A failure, or a timeout, is a failure whatever else
    is known. Without a record the exit code is unknown: in a folder of an older loadcheck
    (no records) a run with fewer tests than the others was stopped midway; in a folder with
    records, the run's loadcheck was stopped before it could write one.
    """
    if run['failed'] or run.get('timed_out'):
        return 'failed'
    code = run.get('exit_code')
    if code is None:
        if folder_recorded:
            return 'incomplete'
        return 'clean' if run['tests'] == most_tests else 'incomplete'
    if code == 0:
        return 'clean'
    return 'incomplete' if code == INTERRUPTED else 'failed'


def tally(folders: list[Path], given_codes: dict | None = None) -> dict:
    """Count the loaded runs of several series per code.

    ``given_codes``: folder -> the commit its runs ran, for folders of an older loadcheck
    whose runs have no record of it (a run's own record wins); its fingerprint is taken
    from this checkout's git history when the commit is in it.

    Runs are grouped by code fingerprint (:func:`code_fingerprint`): commits that differ
    only in documentation are one code.

    Returns
    -------
    dict
        ``runs``: one row per run (:func:`read_series`) (folder, run, commit, code, seconds,
        load average, tests, ``status`` from :func:`run_status`, failed tests); ``by_code``:
        per code (the fingerprint; the commit when it has none, ``unknown`` without either;
        ``+dirty`` for a modified checkout) its commits, the complete runs, the clean ones,
        and the failed tests in the order met.
    """
    repo = test_dir().parent
    rows, by_code = [], {}
    for folder in folders:
        series = read_series(Path(folder))
        most_tests = max((r['tests'] for r in series), default=0)
        recorded = any(r['recorded'] for r in series)
        given = (given_codes or {}).get(folder)
        given_code = ({'commit': given, 'fingerprint': code_fingerprint(repo, given), 'dirty': None}
                      if given else None)
        for r in series:
            code = dict(r.get('code') or {})
            if not code.get('commit') and given_code:
                code = given_code
            commit = code.get('commit') or 'unknown'
            key = code.get('fingerprint') or commit
            if code.get('dirty'):
                key += '+dirty'
            failed = [f['test'] for f in r['failed']]
            status = run_status(r, most_tests, recorded)
            rows.append({'folder': r['folder'], 'run': r['run'], 'commit': commit, 'code': key,
                         'seconds': r.get('seconds'), 'load_average_mean': r.get('load_average_mean'),
                         'tests': r['tests'], 'status': status, 'failed': failed})
            if status == 'incomplete':
                continue
            entry = by_code.setdefault(key, {'commits': [], 'runs': 0, 'clean': 0, 'failed': []})
            if commit not in entry['commits']:
                entry['commits'].append(commit)
            entry['runs'] += 1
            entry['clean'] += status == 'clean'
            if status == 'failed':
                entry['failed'] += [f"{r['folder']}/run{r['run']}: {t}"
                                    for t in failed or [f"(exit code {r.get('exit_code')})"]]
    return {'runs': rows, 'by_code': by_code}


def render_tally(table: dict) -> str:
    """Return the text of a :func:`tally`: one line per run, then one per code."""
    lines = []
    for r in table['runs']:
        load = r['load_average_mean'] if r['load_average_mean'] is not None else '?'
        seconds = f"{r['seconds']:.0f} s" if r['seconds'] is not None else '?'
        verdict = {'clean': 'clean', 'incomplete': 'incomplete (stopped midway)'}.get(
            r['status'], 'FAILED ' + ', '.join(r['failed'] or ['(exit code)']))
        lines.append(f"{r['folder']}/run{r['run']}  {r['commit'][:12]}  {r['tests']} tests  "
                     f"{seconds}  load {load}  {verdict}")
    for code, e in table['by_code'].items():
        commits = ', '.join(c[:12] for c in e['commits'])
        lines.append(f"code {code} (commits {commits}): {e['clean']} clean of {e['runs']} "
                     'complete loaded runs')
    return '\n'.join(lines)


def render(report: dict) -> str:
    """Return the text table of a :func:`loadcheck` report."""
    lines = [f"{report['runs']} run(s), {report['failed_runs']} with a failure; "
             f"load average per run {report['load_average_mean']}; "
             f"seconds {report['seconds']}; tests per run {report['tests_per_run']}"]
    for test, e in report['failures_by_test'].items():
        lines.append(f"  {e['failed_runs']}/{report['runs']}  {test}  (runs {e['runs']}): "
                     f"{e['first_message']}")
    for text, n in report['skips'].items():
        lines.append(f'  skipped {n}x  {text}')
    lines.append(f"logs and junit files: {report['out_dir']}")
    return '\n'.join(lines)
