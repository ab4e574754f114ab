"""Helpers for the tests of the ROS tools that ``./dev`` sets up (tools/ros_tools.sh).

Every command runs as a user would run it: ``bash -c 'source .venv/ros_setup.bash &&
exec CMD'``, with the test process's ROS_DOMAIN_ID and loopback discovery
(test/conftest.py). CLI calls that can use the ros2 daemon pass ``--no-daemon``;
:func:`stop_daemon` stops one that another verb may have started.

Where the vendored sources are missing (a clone without ../shared), the tests that
need the tools skip with the set-up's reason; where they are present but the tools
are not set up, the tests fail: on this machine and in CI they must run.
"""
from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

# log_errors: re-exported for the tests that import their helpers from here
from grip_force_ros.lab.processes import (STACK_DUMP_WAIT, child_setup, domain_ports,  # noqa: F401
                                          log_errors, request_stacks)

ROOT = Path(__file__).resolve().parents[1]
VENV = Path(sys.prefix)
SETUP_FILE = VENV / 'ros_setup.bash'
STATUS_FILE = VENV / 'ros_tools.status'


def vendor_dir() -> Path:
    """Where ./dev looks for the vendored sources ($GRIP_FORCE_VENDOR, else ../shared/vendor)."""
    return Path(os.environ.get('GRIP_FORCE_VENDOR') or ROOT.parent / 'shared' / 'vendor')


def require_ros_tools() -> None:
    """Skip (no vendored sources) or fail (sources there, tools not set up)."""
    if SETUP_FILE.is_file():
        return
    status = STATUS_FILE.read_text().strip() if STATUS_FILE.is_file() else 'never set up (run ./dev setup)'
    if vendor_dir().is_dir():
        pytest.fail(f'the vendored sources are at {vendor_dir()} but the ROS tools are not set '
                    f'up in {VENV}: {status}')
    pytest.skip(f'ROS tools not set up: {status}')


def ros_env(**extra: str) -> dict[str, str]:
    env = dict(os.environ)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env.setdefault('ROS_DOMAIN_ID', str(100 + os.getpid() % 100))
    env.update(extra)
    return env


def sourced(*args: str) -> list[str]:
    """Return the command line that runs ``args`` after sourcing the setup file."""
    return ['bash', '-c', 'source "$0" && exec "$@"', str(SETUP_FILE), *args]


#: A Fast DDS log line, which Fast DDS writes to stdout, in colour: ``ros2 lifecycle get``
#: can print ``<ESC>[37;1m2026-11-27 ... [RTPS_TRANSPORT_SHM Error] ... open_and_lock_file
#: failed -> Function open_port_internal<ESC>[m`` before its answer (the shared-memory
#: transport falls back to UDP; the answer is right).
FASTDDS_LOG_LINE = re.compile(r'^\x1b\[[0-9;]*m\d{4}-\d\d-\d\d .*\b(Error|Warning|Info)\b')


def run(*args: str, timeout: float = 60.0, cwd: Path | str | None = None,
        env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    """Run a command in the sourced environment; output captured as text.

    Fast DDS's own log lines are moved from stdout to the end of stderr: stdout is the
    command's answer, as the tests parse it.
    """
    done = subprocess.run(sourced(*args), capture_output=True, text=True, timeout=timeout,
                          cwd=cwd or ROOT, env=env or ros_env())
    lines = done.stdout.splitlines(keepends=True)
    logged = [line for line in lines if FASTDDS_LOG_LINE.match(line)]
    if logged:
        done.stdout = ''.join(line for line in lines if not FASTDDS_LOG_LINE.match(line))
        done.stderr = (done.stderr or '') + ''.join(logged)
    return done


#: Longest a ros2 CLI call that talks to a node's service may take (s) before it counts as
#: hung. A normal call takes 3-10 s on a loaded 2-core machine (Python start-up, a 2 s
#: spin). The verbs (``ros2 lifecycle``, ``ros2 service call``) wait for the answer without
#: a timeout, and Fast DDS drops an answer whose client reader the server has not yet
#: discovered 100 ms after the request (rmw_fastrtps #390, #467: "client will not receive
#: response"): such a call never returns. py-spy on one under load: ``call_get_states``
#: waiting in ``spin_until_future_complete``, the request sent.
CLI_CALL_TIMEOUT = 30.0


def cli_once(env, *args: str) -> subprocess.CompletedProcess:
    """``ros2 ARGS`` once; a call hung past :data:`CLI_CALL_TIMEOUT` returns with code -1.

    For the verbs that are not idempotent (a transition, a service call): the caller decides
    what a lost answer means.
    """
    return retry(lambda: run('ros2', *args, env=env, timeout=CLI_CALL_TIMEOUT), lambda r: True,
                 timeout=0)


def cli(env, *args: str, timeout: float = 240.0, until=None) -> subprocess.CompletedProcess:
    """``ros2 ARGS`` for a read-only verb, again while it hung or the node was not discovered yet.

    A hung call (past :data:`CLI_CALL_TIMEOUT`, return code -1) is a lost answer, tried
    again; ``timeout`` leaves room for several. ``until(result)``, when given, must hold too
    (a graph query tried until the entities it waits for show).
    """
    return retry(lambda: run('ros2', *args, env=env, timeout=CLI_CALL_TIMEOUT),
                 lambda r: (r.returncode != -1 and 'Node not found' not in r.stdout + r.stderr
                            and (until is None or until(r))),
                 timeout=timeout)


def lifecycle_transition(env, node: str, transition: str, confirm,
                         timeout: float = 240.0) -> tuple[subprocess.CompletedProcess, bool]:
    """``ros2 lifecycle set NODE TRANSITION``; a call whose answer was lost is confirmed apart.

    A transition is not idempotent: a call that hung (:data:`CLI_CALL_TIMEOUT`) may have
    made it, and calling again would be refused. So after a hung call ``confirm()`` (for
    example ``ros2 lifecycle get`` shows the target state, or the process ended after
    ``shutdown``) decides: made, or tried again.

    Returns
    -------
    (CompletedProcess, bool)
        The last call, and whether its answer was lost and the transition confirmed apart
        (the caller then checks the state itself, not the CLI's words).
    """
    deadline = time.monotonic() + timeout
    while True:
        got = cli_once(env, 'lifecycle', 'set', node, transition, '--no-daemon', '--spin-time', '2')
        if got.returncode != -1 and 'Node not found' not in got.stdout + got.stderr:
            return got, False
        if got.returncode == -1 and confirm():
            return got, True
        if time.monotonic() > deadline:
            return got, False
        time.sleep(0.5)


def start(*args: str, log: Path, cwd: Path | str | None = None,
          env: dict[str, str] | None = None) -> subprocess.Popen:
    """Start a long-running command (``exec``-ed: the pid is the command's) in its own session.

    As the package's nodes (``lab.processes.child_setup``): SIGINT at its default (a
    background suite inherits it ignored), and SIGTERM when pytest ends (a stopped loaded
    series once left a test's nodes running through the next CI run).
    """
    out = open(log, 'w')
    try:
        return subprocess.Popen(sourced(*args), stdout=out, stderr=subprocess.STDOUT,
                                cwd=cwd or ROOT, env=env or ros_env(), start_new_session=True,
                                preexec_fn=child_setup())
    finally:
        out.close()


def retry(fn, ok, timeout: float = 60.0, pause: float = 0.5):
    """Call ``fn()`` until ``ok(result)`` or the timeout; return the last result.

    A ros2 CLI call that hangs past its own timeout (e.g. ``ros2 lifecycle get`` before the
    node's services are discovered) is a failed try (return code -1), not the end of the test.
    """
    deadline = time.monotonic() + timeout
    while True:
        try:
            result = fn()
        except subprocess.TimeoutExpired as exc:
            result = subprocess.CompletedProcess(exc.cmd, -1, str(exc.stdout or ''), 'timed out')
        if ok(result) or time.monotonic() > deadline:
            return result
        time.sleep(pause)


def stop(proc: subprocess.Popen, sig: int | None = signal.SIGINT, group: bool = False,
         timeout: float = 30.0) -> int | None:
    """Signal the process or its group (``sig`` None: none) and wait; kill its group if it does not end."""
    if sig is not None and proc.poll() is None:
        if group:
            os.killpg(proc.pid, sig)
        else:
            proc.send_signal(sig)
    try:
        return proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
        return None


_STARTED = re.compile(r'\[(?P<name>[\w.]+)-\d+\]: process started with pid \[(?P<pid>\d+)\]')
#: ``ros2 launch`` sends SIGTERM this long after its SIGINT (its ``sigterm_timeout``), SIGKILL
#: 10 s later; the stacks are asked for just before its SIGTERM.
LAUNCH_SIGTERM_AFTER = 5.0


def stop_launch(proc: subprocess.Popen, log: Path, timeout: float = 30.0) -> int | None:
    """Stop a ``ros2 launch`` process with SIGINT, asking a node that hangs for its stacks.

    A node of it still running shortly before launch's SIGTERM is asked for its threads'
    stacks (into the launch log) and its native stacks are taken (gdb: a Fast DDS thread's
    deadlock shows only there); then wait as :func:`stop`, and add the native stacks to the
    log once launch has ended.

    Launch kills a node that ignores its SIGINT and SIGTERM without asking where it was.
    ``run_node``'s own teardown limit covers a hang after
    the node's loop; this covers one anywhere.
    """
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
    try:
        return proc.wait(timeout=LAUNCH_SIGTERM_AFTER - 0.5)
    except subprocess.TimeoutExpired:
        pass
    launched = [int(started['pid']) for started in _STARTED.finditer(log.read_text(errors='replace'))]
    stuck = [pid for pid in launched if request_stacks(pid, wait=0.0)]   # a live one that handles it
    native = {pid: named_native_stacks(pid) for pid in stuck}   # before launch's SIGTERM comes
    code = stop(proc, None, timeout=timeout)      # no second SIGINT: launch goes on as it would
    with open(log, 'a') as out:                   # launch has ended: the log is ours
        for pid, stacks in native.items():
            out.write(f'--- native stacks of pid {pid} (gdb): {stacks}\n')
    return code


def process_tree(pid: int) -> list[int]:
    """``pid`` and its live descendants, parents first (Linux ``/proc/<pid>/task/*/children``)."""
    tree, todo = [], [pid]
    while todo:
        current = todo.pop(0)
        tree.append(current)
        for task in Path(f'/proc/{current}/task').glob('*'):
            try:
                todo += [int(child) for child in (task / 'children').read_text().split()]
            except (OSError, ValueError):
                pass
    return [one for one in tree if Path(f'/proc/{one}').exists()]


def native_stacks(pid: int, timeout: float = 60.0) -> str:
    """Every thread's native stack of process ``pid`` (gdb, batch mode), or why there is none.

    A participant whose Fast DDS threads deadlock (eProsima/Fast-DDS#6502) goes deaf to
    discovery with its Python threads parked in C; only the native stacks show where.
    """
    gdb = shutil.which('gdb')
    if gdb is None:
        return 'no gdb on this machine'
    try:
        got = subprocess.run([gdb, '-p', str(pid), '-batch', '-nx', '-ex', 'thread apply all bt'],
                             capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return f'gdb did not finish in {timeout:.0f} s'
    return got.stdout or got.stderr


#: Fast DDS's deadlock of a participant's own threads (eProsima/Fast-DDS#6502, open): a
#: receive thread, removing a remote writer under the PDP mutex, waits in ``unregister_timer``
#: for the event thread, which waits for that mutex in ``check_remote_participant_liveliness``.
#: The participant receives nothing from then on. Participants that come and go, with a short
#: lease, make it likelier.
FAST_DDS_6502 = ('check_remote_participant_liveliness', 'unregister_timer')


#: Fast DDS's spinning ``set_listener`` (eProsima/Fast-DDS#6513, open): rmw_fastrtps's
#: ``destroy_participant`` begins with ``set_listener(nullptr)``, whose wait for the listener
#: callbacks in progress busy-waits for good when one runs (another participant's leaving).
FAST_DDS_6513 = ('destroy_participant', 'set_listener')
#: ... and the callback it waits for: a receive thread inside one of these, on the listener's mutex.
FAST_DDS_6513_CALLBACKS = ('onParticipantDiscovery', 'onWriterDiscovery', 'onReaderDiscovery')


def known_deadlock(native: str) -> str | None:
    """Name a known deadlock seen in gdb's stacks of one process, or None."""
    if all(frame in native for frame in FAST_DDS_6502):
        return ('Fast DDS deadlock eProsima/Fast-DDS#6502: the event thread in '
                'check_remote_participant_liveliness, a receive thread in unregister_timer')
    if (all(frame in native for frame in FAST_DDS_6513)
            and any(frame in native for frame in FAST_DDS_6513_CALLBACKS)):
        return ('Fast DDS eProsima/Fast-DDS#6513: the participant\'s deletion spinning in '
                'set_listener while a discovery callback of it waits')
    return None


def named_native_stacks(pid: int) -> str:
    """Return :func:`native_stacks` of ``pid`` after the name of a known deadlock they show."""
    stacks = native_stacks(pid)
    return f'{known_deadlock(stacks) or "no known deadlock"}\n{stacks}'


def _socket_inodes(pid: int) -> set[str]:
    """Inodes of the sockets process ``pid`` holds open (``/proc/<pid>/fd``)."""
    inodes = set()
    for fd in Path(f'/proc/{pid}/fd').iterdir():
        try:
            target = os.readlink(fd)
        except OSError:
            continue                                            # closed meanwhile
        if target.startswith('socket:['):
            inodes.add(target[len('socket:['):-1])
    return inodes


def dds_ports_report(domain_id: int, pids) -> str:
    """Tell what Fast DDS's transports hold for ``domain_id``, for a CLI that saw nothing.

    The hypothesis it tests (a CLI that sees no node of the domain): a new participant reuses
    the participant id, so the ports, of one that was killed; it finds a port's shared-memory
    segment a zombie and makes a new one, while the long-lived nodes keep writing into the old
    one they have mapped (eProsima/Fast-DDS#4728). For each of ``pids``: the UDP ports it binds
    in the domain and the ``fastrtps_port`` segments it maps, a ``(deleted)`` one being such
    an orphan; then each segment named (age, lock file). Fast DDS 2.14 maps, beside the
    domain's own port numbers, a segment from one pool shared by every domain on the machine
    (``fastrtps_port7000`` up, the lowest free number). Called only once a test has failed.
    """
    ports = domain_ports(domain_id)
    lines, named = [f'Fast DDS ports of domain {domain_id}:'], set()
    for pid in pids:
        try:
            command = Path(f'/proc/{pid}/cmdline').read_bytes().replace(b'\0', b' ')[:80]
            maps = Path(f'/proc/{pid}/maps').read_text()
            udp = Path(f'/proc/{pid}/net/udp').read_text()      # the network namespace's sockets
            inodes = _socket_inodes(pid)
        except OSError:
            continue                                            # ended meanwhile
        bound = []
        for row in udp.splitlines()[1:]:
            fields = row.split()
            port = int(fields[1].split(':')[1], 16)
            if fields[9] in inodes and port in ports:
                bound.append(port)
        mapped = sorted({line.split(None, 5)[5].replace('/dev/shm/', '') for line in maps.splitlines()
                         if 'fastrtps_port' in line and len(line.split(None, 5)) == 6})
        named.update(m.split()[0] for m in mapped)
        lines.append(f'  pid {pid} {command.decode(errors="replace")}: binds UDP {sorted(bound)}; '
                     f'maps {mapped}')
    now = time.time()
    named.update(f'fastrtps_port{number}' for number in ports)
    for name in sorted(named):
        segment = Path('/dev/shm') / name
        try:
            age = now - segment.stat().st_mtime
        except OSError:
            continue
        lock = ' + lock file' if Path(f'{segment}_el').exists() else ''
        lines.append(f'  {name}: written {age:.0f} s ago{lock}')
    return '\n'.join(lines)


def process_report(proc: subprocess.Popen, log: Path) -> str:
    """Tell what is known of a started command (:func:`start`) that a CLI call did not find.

    Whether it still runs; what Fast DDS's transports hold (:func:`dds_ports_report`); each
    process of its tree asked for its Python stacks (into ``log``, when it handles the
    signal) and its native stacks taken with gdb; then ``log``.
    Called only once a test has failed: it costs seconds.
    """
    code = proc.poll()
    lines = ['the command runs' if code is None else f'the command exited {code}']
    domain = os.environ.get('ROS_DOMAIN_ID')       # the suite's (conftest), which ros_env passes on
    if domain and code is None:                    # first: gdb stops each process a while
        lines.append(dds_ports_report(int(domain), [os.getpid(), *process_tree(proc.pid)]))
    for pid in process_tree(proc.pid) if code is None else []:
        try:
            command = Path(f'/proc/{pid}/cmdline').read_bytes().replace(b'\0', b' ')[:160]
        except OSError:
            continue                                        # ended meanwhile
        asked = 'asked into the log' if request_stacks(pid, wait=0.0) else 'not handled'
        lines.append(f'--- pid {pid} {command.decode(errors="replace")}: Python stacks {asked}; '
                     f'native stacks (gdb): {named_native_stacks(pid)}')
    time.sleep(STACK_DUMP_WAIT)                             # once, for every process asked
    lines += ['--- log:', log.read_text(errors='replace')]
    return '\n'.join(lines)


def stop_daemon(env: dict[str, str] | None = None) -> None:
    """Stop the ros2 daemon of this domain (127.0.0.1:11511+domain) if a verb started one."""
    subprocess.run(sourced('ros2', 'daemon', 'stop'), capture_output=True, text=True,
                   timeout=30, cwd=ROOT, env=env or ros_env())


_FINISHED = re.compile(r'\[(?P<name>[\w.]+)-\d+\]: process has finished cleanly \[pid (?P<pid>\d+)\]')
_DIED = re.compile(r'\[(?P<name>[\w.]+)-\d+\]: process has died \[pid (?P<pid>\d+), '
                   r'exit code (?P<code>-?\d+)')


def launch_exit_codes(text: str) -> dict[str, int]:
    """Exit code of each process, as ``ros2 launch`` reports them in its output."""
    codes = {m['name']: 0 for m in _FINISHED.finditer(text)}
    codes.update({m['name']: int(m['code']) for m in _DIED.finditer(text)})
    return codes
