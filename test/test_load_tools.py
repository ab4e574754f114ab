"""The suite's own tooling for loaded runs: domain reservation, the CPU load, the disk pressure, loadcheck.

No rclpy: the domain locks, the busy processes and the junit tables are plain processes
and files.
"""
import json
import os
import signal
import subprocess
import sys
import textwrap
import time

import psutil
import pytest

from grip_force_ros.lab.bench.load import LoadError, LoadGenerator
from grip_force_ros.lab.bench import loadcheck
from grip_force_ros.lab.bench import pressure as pressure_module
from grip_force_ros.lab.bench.pressure import DIR_PREFIX, DiskPressure, PressureError, make_pressure
from grip_force_ros.lab.bench.loadcheck import (code_fingerprint, parse_junit, render_tally, source_revision,
                                                tabulate, tally)
from grip_force_ros.lab.processes import (ProcessError, domain_locked, held_domains,
                                          pick_domain_ids, reserve_domains)


# ---------------------------------------------------------------- domains
def test_the_suite_holds_its_own_domain():
    own = int(os.environ['ROS_DOMAIN_ID'])
    assert own in held_domains()              # test/conftest.py reserved it
    assert domain_locked(own)                 # seen as taken by any other run
    assert own not in pick_domain_ids(3, start=own)


def test_two_reservations_never_share_a_domain():
    with reserve_domains(2) as a, reserve_domains(2) as b:
        assert len(set(a.ids) | set(b.ids)) == 4
        assert all(domain_locked(d) for d in a.ids + b.ids)
    assert not any(d in held_domains() for d in a.ids + b.ids)
    assert not any(domain_locked(d) for d in a.ids + b.ids)


def test_another_process_cannot_take_a_held_domain():
    with reserve_domains(1) as mine:
        code = textwrap.dedent(f"""
            from grip_force_ros.lab.processes import ProcessError, reserve_domains
            try:
                reserve_domains(1, candidates=[{mine.domain_id}])
            except ProcessError:
                print('refused')
            else:
                print('taken')
        """)
        out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                             timeout=60)
        assert out.stdout.strip() == 'refused', out.stderr
    with pytest.raises(ProcessError):
        reserve_domains(1, candidates=[])


# ---------------------------------------------------------------- load generator
def test_load_generator_refuses_values_beyond_its_bounds():
    for kwargs in ({'workers': 0}, {'workers': 10_000}, {'seconds': 0.0}, {'seconds': 1e9},
                   {'duty': 0.0}, {'duty': 1.5}):
        with pytest.raises(LoadError):
            LoadGenerator(**{'workers': 1, **kwargs})


def test_load_workers_stop_at_their_deadline():
    load = LoadGenerator(1, seconds=0.5).start()
    try:
        deadline = time.monotonic() + 30.0
        while load.running() and time.monotonic() < deadline:
            time.sleep(0.1)
        assert load.running() == 0, 'a worker outlived its deadline'
    finally:
        summary = load.stop()
    assert summary['workers'] == 1 and summary['worker_cpu_s'] > 0


def test_load_workers_never_outlive_their_parent():
    """The parent is SIGKILLed (no clean-up runs): its workers end too."""
    code = textwrap.dedent("""
        import os, sys, time
        from grip_force_ros.lab.bench.load import LoadGenerator
        load = LoadGenerator(2, seconds=120).start()
        print(' '.join(str(p.pid) for p in load.procs), flush=True)
        time.sleep(120)
    """)
    parent = subprocess.Popen([sys.executable, '-c', code], stdout=subprocess.PIPE, text=True)
    pids = [int(p) for p in parent.stdout.readline().split()]
    assert len(pids) == 2
    workers = [psutil.Process(p) for p in pids]
    time.sleep(0.5)
    assert all(w.is_running() for w in workers)
    parent.send_signal(signal.SIGKILL)
    parent.wait()
    gone, alive = psutil.wait_procs(workers, timeout=10)
    assert not alive, [p.pid for p in alive]


# ---------------------------------------------------------------- loadcheck tables
JUNIT = """<?xml version="1.0" encoding="utf-8"?>
<testsuites><testsuite name="pytest" tests="3">
<testcase classname="test.test_ros_nodes" name="test_a" time="1.0"/>
<testcase classname="test.test_ros_nodes" name="test_b" time="1.0">
  <failure message="AssertionError: no instrument state from the sim process">trace</failure></testcase>
<testcase classname="test.test_demo_e2e" name="test_c" time="1.0">
  <skipped message="not built">skip</skipped></testcase>
</testsuite></testsuites>
"""


def test_loadcheck_groups_failures_by_test(tmp_path):
    path = tmp_path / 'run1.xml'
    path.write_text(JUNIT)
    parsed = parse_junit(path)
    assert parsed['tests'] == 3
    assert parsed['failed'] == [{'test': 'test/test_ros_nodes.py::test_b', 'kind': 'failure',
                                 'message': 'AssertionError: no instrument state from the sim process'}]
    runs = [dict(parsed, run=1, exit_code=1, seconds=10.0, load_average_mean=4.0),
            dict(parse_junit(path), run=2, exit_code=1, seconds=11.0, load_average_mean=4.2),
            {'run': 3, 'exit_code': 0, 'seconds': 9.0, 'load_average_mean': 3.9, 'tests': 3,
             'failed': [], 'skipped': []}]
    table = tabulate(runs)
    assert table['runs'] == 3 and table['failed_runs'] == 2
    entry = table['failures_by_test']['test/test_ros_nodes.py::test_b']
    assert entry['failed_runs'] == 2 and entry['runs'] == [1, 2]
    assert table['skips'] == {'test/test_demo_e2e.py::test_c: not built': 2}


def test_a_failed_run_keeps_its_temporary_files_and_a_passed_one_does_not(tmp_path):
    """A failed loaded run's node logs are its best witness: loadcheck gives each run its own
    pytest temporary folder (``run<k>.tmp``) and removes it only when the run passed (not
    left to pytest's rotation of the user's numbered folders)."""
    from grip_force_ros.lab.bench.loadcheck import run_once
    for name, verdict in (('test_ok.py', 'True'), ('test_bad.py', 'False')):
        (tmp_path / name).write_text(textwrap.dedent(f"""
            def test_writes_a_log(tmp_path):
                (tmp_path / 'node.log').write_text('what the node said')
                assert {verdict}
        """))
    out = tmp_path / 'out'
    out.mkdir()
    passed = run_once(1, out, workers=0, select='not nothing', files=[str(tmp_path / 'test_ok.py')])
    failed = run_once(2, out, workers=0, select='not nothing', files=[str(tmp_path / 'test_bad.py')])
    assert passed['failed'] == [] and 'temporary_files' not in passed
    assert not (out / 'run1.tmp').exists()
    assert len(failed['failed']) == 1 and failed['failed'][0]['test'].endswith('::test_writes_a_log'), failed
    assert failed['temporary_files'] == str(out / 'run2.tmp')
    assert [p.read_text() for p in (out / 'run2.tmp').rglob('node.log')] == ['what the node said']
    # each run leaves its record, with the code it ran (this checkout's, as git sees it)
    record = json.loads((out / 'run2.json').read_text())
    assert record['failed'] == failed['failed']
    assert record['code'] == source_revision(loadcheck.test_dir().parent)


def git(repo, *args):
    done = subprocess.run(['git', '-C', str(repo), '-c', 'user.name=t', '-c', 'user.email=t@t',
                           *args], capture_output=True, text=True, check=True)
    return done.stdout.strip()


def test_code_fingerprint_ignores_documentation_and_nothing_else(tmp_path):
    """A docs-only commit runs the same code (same fingerprint, a series goes on counting);
    any other file starts a new count; an uncommitted change to code is ``dirty``."""
    git(tmp_path, 'init', '-q')
    (tmp_path / 'docs').mkdir()
    for name, text in (('node.py', 'x = 1\n'), ('docs/guide.md', 'a\n'), ('README.md', 'r\n')):
        (tmp_path / name).write_text(text)
    git(tmp_path, 'add', '-A')
    git(tmp_path, 'commit', '-q', '-m', 'one')
    first = source_revision(tmp_path)
    assert first['commit'] == git(tmp_path, 'rev-parse', 'HEAD') and first['dirty'] is False
    (tmp_path / 'docs' / 'guide.md').write_text('b\n')
    assert source_revision(tmp_path)['dirty'] is False           # documentation only
    git(tmp_path, 'commit', '-q', '-am', 'docs')
    second = source_revision(tmp_path)
    assert second['commit'] != first['commit'] and second['fingerprint'] == first['fingerprint']
    (tmp_path / 'node.py').write_text('x = 2\n')
    assert source_revision(tmp_path)['dirty'] is True
    git(tmp_path, 'commit', '-q', '-am', 'code')
    assert source_revision(tmp_path)['fingerprint'] != first['fingerprint']
    assert code_fingerprint(tmp_path, '0' * 40) is None           # not a commit of the repo
    assert source_revision(tmp_path / 'nowhere') == {'commit': None, 'fingerprint': None, 'dirty': None}


def write_run(folder, index, failed=(), tests=3, record=None, junit=True):
    """A run's junit file (``failed``: test names) and, given ``record``, its run record;
    ``junit=False``: the record only (a run killed at its timeout writes no junit file)."""
    folder.mkdir(exist_ok=True)
    cases = ''.join(f'<testcase classname="test.test_x" name="t{k}" time="1.0"/>'
                    for k in range(tests - len(failed)))
    cases += ''.join(f'<testcase classname="test.test_x" name="{name}" time="1.0">'
                     f'<failure message="AssertionError: {name}">trace</failure></testcase>'
                     for name in failed)
    (folder / f'run{index}.xml').write_text(
        f'<testsuites><testsuite name="pytest" tests="{tests}" time="700.5">{cases}</testsuite></testsuites>')
    if record is not None:
        (folder / f'run{index}.json').write_text(json.dumps(
            {'run': index, 'seconds': 700.5, 'load_average_mean': 4.1,
             **parse_junit(folder / f'run{index}.xml'), **record}))
    if not junit:
        (folder / f'run{index}.xml').unlink()


def test_tally_counts_clean_runs_per_code_and_leaves_stopped_runs_out(tmp_path):
    """Two series of one code (one by an older loadcheck without run records, its code given)
    and one of another: clean of complete per code; a run stopped midway (exit code 2, or
    fewer tests than its folder's others without a record, or no record where the others
    have one: its loadcheck stopped) is neither clean nor failed; a run killed at its timeout,
    which leaves only its record, is a failure, not left uncounted."""
    same = {'commit': 'a' * 40, 'fingerprint': 'f1', 'dirty': False}
    docs_later = {'commit': 'b' * 40, 'fingerprint': 'f1', 'dirty': False}
    other = {'commit': 'c' * 40, 'fingerprint': 'f2', 'dirty': False}
    new, old = tmp_path / 'new', tmp_path / 'old'
    write_run(new, 1, record={'exit_code': 0, 'code': same})
    write_run(new, 2, failed=['test_race'], record={'exit_code': 1, 'code': docs_later})
    write_run(new, 3, tests=2, record={'exit_code': 2, 'code': docs_later})     # stopped
    write_run(new, 4, record={'exit_code': 0, 'code': other})
    write_run(new, 5, record={'exit_code': -9, 'timed_out': True, 'code': other,
                              'failed': [{'test': '(session)'}]}, junit=False)       # hung
    write_run(new, 6)                                       # all its tests; its loadcheck stopped
    write_run(old, 1)
    write_run(old, 2, tests=1)                                                     # stopped
    write_run(old, 3, failed=['test_race'])
    (old / 'run4.log').write_text('killed before its junit file')
    table = tally([new, old], {old: 'old-label'})
    assert [(r['run'], r['status']) for r in table['runs']] == [
        (1, 'clean'), (2, 'failed'), (3, 'incomplete'), (4, 'clean'), (5, 'failed'),
        (6, 'incomplete'), (1, 'clean'), (2, 'incomplete'), (3, 'failed')]
    assert table['by_code'] == {
        'f1': {'commits': ['a' * 40, 'b' * 40], 'runs': 2, 'clean': 1,
               'failed': [f'{new}/run2: test/test_x.py::test_race']},
        'f2': {'commits': ['c' * 40], 'runs': 2, 'clean': 1, 'failed': [f'{new}/run5: (session)']},
        'old-label': {'commits': ['old-label'], 'runs': 2, 'clean': 1,
                      'failed': [f'{old}/run3: test/test_x.py::test_race']}}
    text = render_tally(table)
    assert 'code f1 (commits aaaaaaaaaaaa, bbbbbbbbbbbb): 1 clean of 2 complete loaded runs' in text
    assert f'{old}/run2  old-label  1 tests  700 s  load ?  incomplete (stopped midway)' in text


def test_tally_command_prints_the_table_and_refuses_a_missing_folder(tmp_path, capsys):
    from grip_force_ros.lab.cli import main
    write_run(tmp_path / 's', 1, record={'exit_code': 0, 'code': {'commit': 'a' * 40, 'fingerprint': 'f1'}})
    assert main(['loadcheck', '--tally', str(tmp_path / 's'), '--json']) == 0
    assert json.loads(capsys.readouterr().out)['by_code']['f1']['clean'] == 1
    assert main(['loadcheck', '--tally', str(tmp_path / 'nowhere')]) == 2
    assert 'no such folder' in capsys.readouterr().err


def test_load_command_refuses_values_beyond_its_bounds(capsys):
    from grip_force_ros.lab.cli import main
    assert main(['load', '--seconds', '0']) == 2
    assert 'seconds' in capsys.readouterr().err
    assert main(['loadcheck', '--runs', '0']) == 2


def test_a_stopped_loadcheck_stops_its_run_and_what_the_run_started(tmp_path):
    """SIGTERM to `grip-force loadcheck`: the pytest run in progress gets SIGINT (its
    fixtures' teardown runs) and its session is killed after the grace; the load ends too."""
    (tmp_path / 'test_slow.py').write_text(textwrap.dedent(f"""
        import os, subprocess, time
        import pytest

        @pytest.fixture
        def child():
            proc = subprocess.Popen(['sleep', '300'])      # in the run's session
            (open({str(tmp_path / 'pids')!r}, 'w')).write(f'{{os.getpid()}} {{proc.pid}}')
            yield proc
            open({str(tmp_path / 'teardown')!r}, 'w').write('ran')
            proc.terminate()

        def test_slow(child):
            time.sleep(300)
    """))
    runner = subprocess.Popen([sys.executable, '-m', 'grip_force_ros.lab.cli', 'loadcheck', '--runs',
                               '1', '--workers', '1', '--duty', '0.2', '--select', 'not nothing',
                               '--files', str(tmp_path / 'test_slow.py'),
                               '--out', str(tmp_path / 'out')],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    pids_file = tmp_path / 'pids'
    deadline = time.monotonic() + 60
    while not pids_file.is_file() or len(pids_file.read_text().split()) < 2:
        assert time.monotonic() < deadline and runner.poll() is None, runner.communicate()
        time.sleep(0.2)
    procs = [psutil.Process(int(p)) for p in pids_file.read_text().split()]
    workers = [p for p in psutil.Process(runner.pid).children()
               if 'grip_force_ros.lab.bench.load' in ' '.join(p.cmdline())]
    assert len(workers) == 1
    runner.send_signal(signal.SIGTERM)
    runner.wait(timeout=60)
    gone, alive = psutil.wait_procs(procs + workers, timeout=30)
    assert not alive, [p.cmdline() for p in alive]
    assert (tmp_path / 'teardown').read_text() == 'ran'     # SIGINT first: fixtures torn down


def test_a_run_that_does_not_answer_is_killed_with_the_processes_it_started(tmp_path, monkeypatch):
    """A run past its timeout that ignores SIGINT (e.g. pytest deadlocked in rmw with the GIL
    held): it and the process it started in another session are both gone when ``run_once``
    returns, not left running beside the next run."""
    (tmp_path / 'test_stuck.py').write_text(textwrap.dedent(f"""
        import os, signal, subprocess, time

        def test_stuck():
            node = subprocess.Popen(['sleep', '300'], start_new_session=True)
            open({str(tmp_path / 'pids')!r}, 'w').write(f'{{os.getpid()}} {{node.pid}}')
            signal.signal(signal.SIGINT, signal.SIG_IGN)      # deaf, as a deadlocked process
            time.sleep(300)
    """))
    monkeypatch.setattr(loadcheck, 'STOP_GRACE', 1.0)
    result = loadcheck.run_once(1, tmp_path, workers=0, select='not nothing',
                                files=[str(tmp_path / 'test_stuck.py')], timeout=10.0)
    assert result['timed_out'] and result['exit_code'] == -signal.SIGKILL, result
    pids = [int(p) for p in (tmp_path / 'pids').read_text().split()]
    gone, alive = psutil.wait_procs([psutil.Process(p) for p in pids if psutil.pid_exists(p)],
                                    timeout=10)
    assert not alive, [p.cmdline() for p in alive]


# ---------------------------------------------------------------- disk and memory pressure
def _tree_bytes(path):
    """Bytes of the files under ``path`` (0 once it is gone)."""
    total = 0
    for root, _dirs, files in os.walk(path):
        for name in files:
            try:
                total += os.path.getsize(os.path.join(root, name))
            except OSError:
                pass
    return total


def test_disk_pressure_refuses_values_beyond_its_bounds(tmp_path):
    for kwargs in ({'writers': -1}, {'writers': 10_000}, {'seconds': 0.0}, {'seconds': 1e9},
                   {'file_mb': 0.0}, {'file_mb': 1e7}, {'writers': 16, 'file_mb': 4096},
                   {'fsync_mb': 0.0}, {'rate_mb_s': -1.0}, {'evict_rate': -1.0},
                   {'memory_mb': -1.0}, {'memory_mb': 1e9},
                   {'writers': 0, 'evict_rate': 0.0, 'memory_mb': 0.0}):
        with pytest.raises(PressureError):
            DiskPressure(**{'writers': 1, 'file_mb': 1.0, 'directory': tmp_path, **kwargs})
    assert issubclass(PressureError, LoadError)
    with pytest.raises(PressureError):
        make_pressure('sideways')


def test_disk_pressure_writes_fsyncs_evicts_within_its_size_bound_and_cleans_up(tmp_path):
    """A tiny run: one writer of a 2 MB file at 4 MB/s, the evictor, 8 MB of memory."""
    pressure = DiskPressure(writers=1, seconds=60.0, file_mb=2.0, fsync_mb=0.5, rate_mb_s=4.0,
                            evict_rate=200.0, memory_mb=8.0, directory=tmp_path)
    largest = 0
    with pressure:
        assert pressure.not_ready == [] and pressure.running() == 3
        directory = pressure.directory
        assert directory.parent == tmp_path and directory.name.startswith(DIR_PREFIX)
        end = time.monotonic() + 1.5
        while time.monotonic() < end:
            largest = max(largest, _tree_bytes(directory))
            time.sleep(0.05)
    summary = pressure.last_summary
    assert 0 < largest <= pressure.bytes_limit == 2 * 2**20
    assert summary['kind'] == 'disk' and summary['bytes_limit'] == pressure.bytes_limit
    assert summary['bytes_written'] > 0 and summary['fsyncs'] > 0
    assert 0 < summary['largest_file_bytes'] <= pressure.bytes_limit
    assert summary['files_evicted'] > 0 and summary['evict_targets'] > 0
    assert summary['memory_touched_bytes'] > 0
    assert summary['wall_s'] > 0 and summary['drop_caches'] == 0     # never unless asked
    assert sorted(c['role'] for c in summary['children']) == ['evictor', 'memory', 'writer']
    assert all(c['ended_by'] == 'SIGTERM' for c in summary['children']), summary['children']
    assert summary['cleaned'] and not directory.exists() and list(tmp_path.iterdir()) == []
    json.dumps(summary)                             # a plain dict, as the commands print it


def test_disk_pressure_stops_at_its_deadline_and_removes_its_files_itself(tmp_path):
    pressure = DiskPressure(writers=1, seconds=1.0, file_mb=1.0, rate_mb_s=2.0, evict_rate=50.0,
                            directory=tmp_path).start()
    try:
        deadline = time.monotonic() + 30.0
        while pressure.running() and time.monotonic() < deadline:
            time.sleep(0.1)
        assert pressure.running() == 0, 'a child outlived its deadline'
        assert list(tmp_path.iterdir()) == []       # before stop(): the children cleaned up
    finally:
        summary = pressure.stop()
    assert summary['bytes_written'] > 0
    assert [c['ended_by'] for c in summary['children']] == ['deadline', 'deadline']


def test_disk_pressure_leaves_no_file_when_its_parent_is_killed(tmp_path):
    """The parent is SIGKILLed (no clean-up runs in it): its children remove the files."""
    code = textwrap.dedent(f"""
        import time
        from grip_force_ros.lab.bench.pressure import DiskPressure
        p = DiskPressure(writers=2, seconds=120, file_mb=2, rate_mb_s=2, evict_rate=50,
                         memory_mb=8, directory={str(tmp_path)!r}).start()
        print(p.directory, ' '.join(str(q.pid) for _, q in p.procs), flush=True)
        time.sleep(120)
    """)
    parent = subprocess.Popen([sys.executable, '-c', code], stdout=subprocess.PIPE, text=True)
    directory, *pids = parent.stdout.readline().split()
    children = [psutil.Process(int(p)) for p in pids]
    assert len(children) == 4
    deadline = time.monotonic() + 30.0
    while _tree_bytes(directory) == 0:              # the writers have begun
        assert time.monotonic() < deadline, 'no file written'
        time.sleep(0.05)
    parent.send_signal(signal.SIGKILL)
    parent.wait()
    gone, alive = psutil.wait_procs(children, timeout=10)
    assert not alive, [p.pid for p in alive]
    deadline = time.monotonic() + 5.0
    while os.path.exists(directory) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not os.path.exists(directory), list(os.walk(directory))
    assert list(tmp_path.iterdir()) == []


class _CountedChild:
    """A stand-in for a pressure child's stop condition: done after ``ticks`` checks."""

    def __init__(self, ticks):
        self.ticks = ticks
        self.deadline = time.monotonic() + 60.0

    def done(self):
        self.ticks -= 1
        return self.ticks < 0

    def sleep(self, seconds):
        pass


def test_the_evictor_advises_each_file_and_says_why_drop_caches_was_refused(tmp_path, monkeypatch):
    files = []
    for k in range(3):
        files.append(tmp_path / f'f{k}')
        files[-1].write_bytes(b'x' * 4096)
    monkeypatch.setattr(pressure_module, 'DROP_CACHES', tmp_path / 'nowhere' / 'drop_caches')
    out = pressure_module.evict_loop(_CountedChild(1), rate=80.0, drop_caches=True,
                                     targets=files + [tmp_path / 'missing'])
    assert out['files_evicted'] == 3 and out['evict_refused'] == 1 and out['evict_passes'] == 1
    assert out['bytes_evicted'] == 3 * 4096
    assert out['drop_caches'] == 0 and 'FileNotFoundError' in out['drop_caches_refused']
    targets = pressure_module.evict_targets()
    names = {p.name for p in targets}
    assert 'pressure.py' in names and any('.so' in n for n in names)      # the package, libraries
    assert len(targets) <= pressure_module.MAX_EVICT_FILES


def test_make_pressure_builds_each_kind():
    assert make_pressure('none').stop() == {'kind': 'none'}
    assert isinstance(make_pressure('cpu', seconds=1.0, workers=1), LoadGenerator)
    assert isinstance(make_pressure('disk', seconds=1.0, writers=1, file_mb=1.0), DiskPressure)
    both = make_pressure('both', seconds=1.0, workers=1, writers=1, file_mb=1.0)
    assert both.kind == 'both' and set(both.generators) == {'cpu', 'disk'}


def test_pressure_commands_refuse_values_beyond_their_bounds(capsys):
    from grip_force_ros.lab.cli import main
    assert main(['load', '--kind', 'disk', '--file-mb', '1e7']) == 2
    assert 'file_mb' in capsys.readouterr().err
    assert main(['bench', '--pressure', 'disk', '--disk-file-mb', '1e7', '--parts', 'model']) == 2
    assert 'file_mb' in capsys.readouterr().err
    assert main(['demo', '--pressure', 'disk', '--disk-memory-mb', '1e9']) == 2
    assert 'memory_mb' in capsys.readouterr().err


def test_changelog_and_markdown_are_documentation_for_the_tally():
    """A commit that changes only README, CHANGELOG.rst or docs/ keeps the code's fingerprint."""
    from grip_force_ros.lab.bench.loadcheck import is_documentation
    docs = ('README.md', 'CHANGELOG.rst', 'docs/dvrk.md', 'docs/figures/demo_compare.png')
    assert all(is_documentation(p) for p in docs)
    assert not any(is_documentation(p) for p in ('grip_force_ros/nodes/controller.py',
                                                 'config/paper_needle_driver.yaml', 'setup.cfg'))
