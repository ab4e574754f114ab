"""Nodes as child processes: their environment, command line and lifetime. No rclpy here.

The one owner of

* the ROS environment of a child (:func:`ros_environment`): DDS discovery on
  loopback unless the user chose a range (:func:`ensure_local_discovery`, the
  package's only Python copy of that rule), the domain id the caller gives;
* the command line of a node (:func:`node_command`): the node's ``main`` with its teardown
  watched (``python -m grip_force_ros.lab.node_process <name>``), or what
  ``GRIP_FORCE_NODE_<NAME>`` says; then ``--ros-args`` (:func:`ros_args`) with
  every value as the YAML literal ROS parses (:func:`ros_arg_value`);
* the process (:class:`NodeProcess`): started with its output in a log file,
  paused, stopped with escalation (SIGINT, SIGTERM, SIGKILL) whatever happens;
  :class:`ProcessGroup` starts several and stops them together, in reverse order;
* the scheduling of a 1 kHz node (:func:`realtime`, :func:`can_use_realtime`,
  :func:`scheduling_of`): SCHED_FIFO as ``chrt -f N`` or ros2_control's controller manager
  (``thread_priority``, 50) give it, where the machine permits;
* a free ROS domain on this machine (:func:`pick_domain_ids`), held for a run
  (:func:`reserve_domains`: no DDS port bound, and a lock file no other run holds).

The demo, the benchmarks, the fault check, the soak and the tests start nodes
through this module. Nodes inside this process (a test reaching into a node):
:class:`grip_force_ros.lab.harness.RosRunner`. A node's teardown watcher, its stack signal and
libc's ``prctl``: :mod:`grip_force_ros.lab.node_process`.
"""
from __future__ import annotations

import fcntl
import os
import re
import shlex
import signal
import subprocess
import sys
import tempfile
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, MutableMapping, Sequence

from grip_force_ros.lab.node_process import PRCTL, STACK_DUMP_SIGNAL, STACK_DUMP_WAIT

#: The node executables of the package (console scripts of setup.py).
NODE_EXECUTABLES = ('controller', 'sim_instrument', 'master')
#: Environment variable of the DDS discovery range, and the package's default for it.
DISCOVERY_RANGE = 'ROS_AUTOMATIC_DISCOVERY_RANGE'
LOCAL_DISCOVERY = 'LOCALHOST'

#: Fast DDS / RTPS port mapping (DDSI-RTPS spec 9.6.1.1): PB + DG * domain_id.
_PORT_BASE = 7400
_DOMAIN_GAIN = 250
#: Largest domain id whose ports stay valid for every participant on Linux.
MAX_DOMAIN_ID = 101


#: A line of a node's log that shows an error: a Python traceback, or the lines the
#: EventsExecutor writes for an exception it caught in a callback ("[FATAL] ... Exception in
#: 'timers' callback: ..." then "Error occurred at:" and the stack), which hold no "Traceback".
LOG_ERROR = re.compile(r"Traceback|Exception in '\w+' callback|Error occurred at:")


def log_errors(text: str) -> list[str]:
    """Return the lines of a node or launch log that show an error (:data:`LOG_ERROR`)."""
    return [line for line in text.splitlines() if LOG_ERROR.search(line)]


class ProcessError(RuntimeError):
    """A node process could not be started or died early."""


def wait_until(predicate: Callable[[], bool], timeout: float, poll: float = 0.005) -> bool:
    """Poll ``predicate()`` until it is true or ``timeout`` s pass; returns its last value."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(poll)
    return bool(predicate())


def python_module(module: str, *args: str) -> list[str]:
    """Command line running ``python -m module args`` with this interpreter."""
    return [sys.executable, '-m', module, *args]


# ---------------------------------------------------------------- environment
def ensure_local_discovery(env: MutableMapping[str, str] | None = None) -> MutableMapping[str, str]:
    """Keep DDS discovery on this machine unless a range was chosen.

    Parameters
    ----------
    env : mutable mapping, optional
        Environment to complete in place (default: this process's ``os.environ``,
        which rclpy started later in this process reads).

    Returns
    -------
    mutable mapping
        ``env``, with ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` unless it was set.
    """
    env = os.environ if env is None else env
    env.setdefault(DISCOVERY_RANGE, LOCAL_DISCOVERY)
    return env


def ros_environment(domain_id: int | None = None, extra: Mapping[str, str] | None = None,
                    base: Mapping[str, str] | None = None) -> dict[str, str]:
    """Environment of a ROS child process.

    Parameters
    ----------
    domain_id : int, optional
        ``ROS_DOMAIN_ID`` of the child; None keeps the one of ``base`` (e.g. a
        test's own domain, set by its conftest).
    extra : mapping, optional
        Further variables, set last (e.g. ``PYTHONPATH``).
    base : mapping, optional
        Environment to start from (default ``os.environ``; not modified).

    Returns
    -------
    dict
        ``base`` with loopback discovery unless chosen (:func:`ensure_local_discovery`),
        the domain, unbuffered Python output and uncoloured ROS logs unless chosen,
        and ``extra``.
    """
    env = dict(os.environ if base is None else base)
    ensure_local_discovery(env)
    if domain_id is not None:
        env['ROS_DOMAIN_ID'] = str(int(domain_id))
    env.setdefault('PYTHONUNBUFFERED', '1')
    env.setdefault('RCUTILS_COLORIZED_OUTPUT', '0')
    env.update(extra or {})
    return env


#: The set-up's ROS environment file (tools/ros_tools.sh): crtk_msgs, the dVRK client, ros2.
ROS_SETUP_FILE = 'ros_setup.bash'


def ros_tools_environment(base: Mapping[str, str] | None = None,
                          setup_file: str | os.PathLike | None = None) -> dict[str, str]:
    """Return the environment of ``source .venv/ros_setup.bash`` (crtk_msgs, dVRK client, ros2).

    What a node of the ``dvrk`` profile needs: crtk_msgs' typesupport libraries on the
    library path (``PYTHONPATH`` alone is not enough). On a ROS machine with crtk_msgs
    installed the caller's own environment already has it.

    Parameters
    ----------
    base : mapping, optional
        Environment to source the file in (default ``os.environ``).
    setup_file : path, optional
        Default: ``ros_setup.bash`` beside this interpreter's virtual environment.

    Raises
    ------
    ProcessError
        The set-up has not built the ROS tools (with the reason it recorded).
    """
    setup = Path(setup_file) if setup_file else Path(sys.prefix) / ROS_SETUP_FILE
    if not setup.is_file():
        status = Path(sys.prefix) / 'ros_tools.status'
        why = status.read_text().strip() if status.is_file() else 'never set up'
        raise ProcessError(f'the dvrk profile needs crtk_msgs from the ROS tools of the set-up '
                           f'({setup} missing: {why}); run ./dev setup')
    done = subprocess.run(['bash', '-c', 'source "$0" >/dev/null 2>&1 && env -0', str(setup)],
                          env=dict(os.environ if base is None else base), capture_output=True,
                          timeout=60)
    if done.returncode != 0:
        raise ProcessError(f'sourcing {setup} failed: {done.stderr.decode(errors="replace")[-500:]}')
    env = {}
    for item in done.stdout.split(b'\0'):
        key, sep, value = item.decode(errors='replace').partition('=')
        if sep and key:
            env[key] = value
    return env


# ---------------------------------------------------------------- command line
def ros_arg_value(value: Any) -> str:
    """Format a Python value as the YAML literal of ``-p name:=value`` on a ROS command line.

    Strings are quoted (``''`` and ``'true'`` or ``'1.0'`` stay strings), floats keep
    their full precision (``repr``), booleans are ``true``/``false``, sequences lists.
    """
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, (list, tuple)):
        return '[' + ','.join(ros_arg_value(v) for v in value) + ']'
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, str):
        return "'" + value.replace("'", "''") + "'"
    return str(value)


def ros_args(params_file: str | os.PathLike | None = None,
             params: Mapping[str, Any] | None = None, *, node_name: str | None = None,
             remaps: Mapping[str, str] | None = None, log_level: str | None = None) -> list[str]:
    """``--ros-args`` of a node: name remap, parameter file, ``-p`` values, remaps, log level.

    Parameters
    ----------
    params_file : path, optional
        ``--params-file`` (a ROS parameter YAML).
    params : mapping, optional
        Parameter name -> value, after the file (so they win), see :func:`ros_arg_value`.
    node_name : str, optional
        ``-r __node:=<node_name>``.
    remaps : mapping, optional
        Topic remaps ``-r from:=to``.
    log_level : str, optional
        ``--log-level`` (e.g. 'warn').
    """
    out = ['--ros-args']
    if node_name:
        out += ['-r', f'__node:={node_name}']
    if params_file is not None:
        out += ['--params-file', str(params_file)]
    for name, value in (params or {}).items():
        out += ['-p', f'{name}:={ros_arg_value(value)}']
    for src, dst in (remaps or {}).items():
        out += ['-r', f'{src}:={dst}']
    if log_level:
        out += ['--log-level', log_level]
    return out


def node_executable(name: str) -> list[str]:
    """Return the command that runs node ``name`` (without its arguments).

    ``GRIP_FORCE_NODE_<NAME>`` in this process's environment (e.g.
    ``GRIP_FORCE_NODE_SIM_INSTRUMENT``) replaces it, e.g. to run against another
    build or a hardware driver (split like a shell would). Otherwise the node's
    ``main`` run by this interpreter with its teardown watched
    (:func:`grip_force_ros.lab.node_process.main`).

    Raises
    ------
    ValueError
        ``name`` is not one of :data:`NODE_EXECUTABLES`.
    """
    if name not in NODE_EXECUTABLES:
        raise ValueError(f'unknown node executable {name!r}; one of {NODE_EXECUTABLES}')
    override = os.environ.get(f'GRIP_FORCE_NODE_{name.upper()}')
    if override:
        return shlex.split(override)
    return python_module('grip_force_ros.lab.node_process', name)


def node_command(name: str, params_file: str | os.PathLike | None = None,
                 params: Mapping[str, Any] | None = None, **ros_options: Any) -> list[str]:
    """Full command line of node ``name``: :func:`node_executable` + :func:`ros_args`.

    ``ros_options`` are the keyword arguments of :func:`ros_args` (``node_name``,
    ``remaps``, ``log_level``).
    """
    return node_executable(name) + ros_args(params_file, params, **ros_options)


# ---------------------------------------------------------------- scheduling
#: SCHED_FIFO priority of the 1 kHz nodes (sim, controller) where permitted: ros2_control's
#: controller manager uses 50 for its control thread (its ``thread_priority`` default).
DEFAULT_RT_PRIORITY = 50


def master_rt_priority(loop_priority: int) -> int:
    """Return the SCHED_FIFO priority of the master beside a loop at ``loop_priority``.

    Ten below the 1 kHz loop, so that the loop preempts it and other work does not: on a
    busy 2-core machine a master at normal priority was starved past the controller's
    0.1 s master watchdog by a second of Python start-up of a ros2 CLI call. 0 (normal
    scheduling) when the loop is normal.
    """
    return max(1, loop_priority - 10) if loop_priority else 0


def recorder_rt_priority(loop_priority: int) -> int:
    """Return the SCHED_FIFO priority of an in-process recorder beside a loop at ``loop_priority``.

    Ten below the master: the loop and the master preempt it, a busy worker does not. At
    normal priority, under two busy workers, its DDS threads were starved past the
    publishers' KEEP_LAST 10 and the bag lost 100-400 ms of every topic in the middle of a
    task. 0 (normal scheduling) when the loop is normal.
    """
    return max(1, loop_priority - 20) if loop_priority else 0


@contextmanager
def realtime_threads(priority: int):
    """Run the block with this thread under SCHED_FIFO ``priority``; yield the policy as text.

    The threads started inside the block inherit it (a node's DDS receive and event threads,
    an executor's thread), as a child does :func:`realtime`'s; this thread goes back to its
    own scheduling afterwards. ``priority`` 0, or a machine that refuses (no CAP_SYS_NICE):
    nothing changes, and it yields 'normal'.
    """
    if not priority:
        yield 'normal'
        return
    if not 1 <= priority <= 99:
        raise ValueError(f'SCHED_FIFO priority must be 1..99, got {priority}')
    before = os.sched_getscheduler(0), os.sched_getparam(0)
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except OSError:
        before = None              # refused: the block runs as it is (yielded below)
    if before is None:
        yield 'normal'
        return
    try:
        yield f'SCHED_FIFO {priority}'
    finally:
        os.sched_setscheduler(0, before[0], before[1])


def realtime(priority: int) -> Callable[[], None]:
    """Return a ``preexec_fn`` putting the child under SCHED_FIFO ``priority`` (1..99).

    Set before ``exec``, so every thread the process starts (the executor, the DDS
    receive threads) inherits it, as ``chrt -f <priority> <cmd>`` would. Needs
    CAP_SYS_NICE (root or an rtprio limit); raises in the child otherwise. The
    kernel's RT throttling (``sched_rt_runtime_us``) still leaves other work 5 %.
    """
    if not 1 <= priority <= 99:
        raise ValueError(f'SCHED_FIFO priority must be 1..99, got {priority}')

    def apply() -> None:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    return apply


def can_use_realtime(priority: int = 1) -> bool:
    """Whether this process may start SCHED_FIFO children (tried on itself, then undone)."""
    try:
        before = os.sched_getscheduler(0), os.sched_getparam(0)
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
        os.sched_setscheduler(0, before[0], before[1])
        return True
    except (OSError, AttributeError):
        return False


def scheduling_of(pid: int) -> str:
    """Return the scheduling policy of process ``pid`` as text ('SCHED_FIFO 50', 'normal')."""
    try:
        policy = os.sched_getscheduler(pid)
        if policy == os.SCHED_FIFO:
            return f'SCHED_FIFO {os.sched_getparam(pid).sched_priority}'
        if policy == os.SCHED_RR:
            return f'SCHED_RR {os.sched_getparam(pid).sched_priority}'
        return 'normal'
    except OSError:
        return 'unknown'


# ---------------------------------------------------------------- processes
_PR_SET_PDEATHSIG = 1  # prctl option, <linux/prctl.h>


def end_with_parent(sig: int = signal.SIGTERM) -> bool:
    """Ask the kernel to send ``sig`` to this process when the thread that forked it ends.

    Call in a child (a ``preexec_fn``, or first thing in a worker). Linux's
    ``PR_SET_PDEATHSIG`` outlives ``exec``, so a node started by a test, the demo or a
    benchmark does not run on after its parent was killed (seen: a stopped loaded series left
    a test's nodes running through the next CI run). The signal comes when the *forking
    thread* ends, so a parent starts such a child only from a thread that lives as long as
    the child should (:func:`child_setup` does it for the main thread only).

    The signal is sent once, so it must not be one a starting Python loses: SIGINT is (Python
    handles it from its first line, and a KeyboardInterrupt raised inside an import's weakref
    callback is discarded: 27 of 7200 SIGINTs sent in a child's first 30 ms, none of 3000
    SIGTERMs). SIGTERM ends a process that has no
    handler for it yet, and a node that has one (``nodes.lifetime.SignalStop``) stops as on
    Ctrl-C; ``ros2 launch`` handles it too.

    Parameters
    ----------
    sig : int
        Signal to receive (SIGTERM, above; SIGKILL for a worker with nothing to clean up).

    Returns
    -------
    bool
        Whether the kernel took the request (False where ``prctl`` is not available).
    """
    return PRCTL is not None and PRCTL(_PR_SET_PDEATHSIG, int(sig), 0, 0, 0) == 0


#: The line ``faulthandler`` begins each thread's stack with (``Thread 0x...``, and ``Current
#: thread 0x...`` for the thread that handled the signal).
STACK_THREAD_HEADER = re.compile(r'^(?:Current thread|Thread) 0x', re.M)


def catches_signal(pid: int, sig: int) -> bool:
    """Whether process ``pid`` has a handler for ``sig`` (Linux ``/proc/<pid>/status``, SigCgt).

    False where that cannot be read (not Linux, the process gone).
    """
    try:
        with open(f'/proc/{pid}/status') as status:
            for line in status:
                if line.startswith('SigCgt:'):
                    return bool(int(line.split()[1], 16) >> (int(sig) - 1) & 1)
    except (OSError, ValueError, IndexError):
        pass
    return False


def request_stacks(pid: int, wait: float = STACK_DUMP_WAIT) -> bool:
    """Ask process ``pid`` for its threads' stacks in its log (:data:`STACK_DUMP_SIGNAL`).

    Only a process that handles that signal gets it (for any other its default action would
    end the process): True when it was sent, and then ``wait`` s have passed for the process
    to write them (0: the caller waits once for several processes).
    """
    if not catches_signal(pid, STACK_DUMP_SIGNAL):
        return False
    try:
        os.kill(pid, STACK_DUMP_SIGNAL)
    except ProcessLookupError:
        return False
    time.sleep(wait)
    return True


def child_setup(preexec_fn: Callable[[], None] | None = None) -> Callable[[], None]:
    """Run in a child before ``exec``: SIGINT at its default, then ``preexec_fn``.

    A parent started as a background job (``&``, nohup, a CI runner) has SIGINT ignored, and
    its children would inherit that: they could not be stopped with SIGINT, the first step of
    :meth:`NodeProcess.stop` (found by the suite run as a background job). A child started
    from the main thread also ends with its parent (:func:`end_with_parent`, SIGTERM); one
    started from another thread (the fault check restarts the sim from a short-lived thread)
    does not.
    """
    from_main_thread = threading.current_thread() is threading.main_thread()

    def setup() -> None:
        signal.signal(signal.SIGINT, signal.SIG_DFL)
        if from_main_thread:
            end_with_parent()   # SIGTERM: a node shuts down on it, a starting Python cannot lose it
        if preexec_fn is not None:
            preexec_fn()
    return setup


def _both(first: Callable[[], None], then: Callable[[], None] | None) -> Callable[[], None]:
    def run() -> None:
        first()
        if then is not None:
            then()
    return run


class NodeProcess:
    """One node (or any command) in its own process, stopped for sure.

    Parameters
    ----------
    name : str
        Label in reports; the node executable when ``command`` is not given.
    params_file, params : optional
        Arguments of :func:`node_command` (when ``command`` is not given).
    command : sequence of str, optional
        The whole command line (default ``node_command(name, params_file, params)``).
    env : mapping, optional
        The child's whole environment (default :func:`ros_environment`: this
        process's, with loopback discovery unless chosen).
    log_path : path, optional
        File that receives stdout and stderr (default: discarded).
    own_session : bool
        Start the child in its own session: a Ctrl-C at the terminal reaches only
        this process, which then stops the child; signals go to its process group.
    pipe : bool
        Read stdout and stderr from :attr:`popen` ``.stdout`` (text, line-buffered)
        instead of a log file.
    preexec_fn : callable, optional
        Run in the child before ``exec`` (e.g. a scheduling policy).
    rt_priority : int
        0 (normal scheduling), or the SCHED_FIFO priority of the child (1..99) where this
        machine permits it (:func:`can_use_realtime`); where not, the child runs with
        normal scheduling and :attr:`scheduling` says why.

    Raises
    ------
    ProcessError
        The command could not be started.
    """

    def __init__(self, name: str, params_file: str | os.PathLike | None = None,
                 params: Mapping[str, Any] | None = None, *, command: Sequence[str] | None = None,
                 env: Mapping[str, str] | None = None, log_path: str | os.PathLike | None = None,
                 own_session: bool = False, pipe: bool = False,
                 preexec_fn: Callable[[], None] | None = None, rt_priority: int = 0):
        self.name = name
        #: The child's scheduling as asked and got ('normal', 'SCHED_FIFO 50', or why not).
        self.scheduling = 'normal'
        if not 0 <= rt_priority <= 99:
            raise ValueError(f'rt_priority must be 0 (normal) or 1..99, got {rt_priority}')
        if rt_priority:
            if can_use_realtime(rt_priority):
                preexec_fn = _both(realtime(rt_priority), preexec_fn)
                self.scheduling = f'SCHED_FIFO {rt_priority}'
            else:
                self.scheduling = f'normal (SCHED_FIFO {rt_priority} not permitted here)'
        self.command = list(command) if command is not None else node_command(name, params_file, params)
        self.log_path = Path(log_path) if log_path is not None else None
        self.own_session = own_session
        text: dict[str, Any] = {}
        log_file = None
        if pipe:
            stdout, text = subprocess.PIPE, {'text': True, 'bufsize': 1}
        elif self.log_path is not None:
            self.log_path.parent.mkdir(parents=True, exist_ok=True)
            stdout = log_file = open(self.log_path, 'wb')  # noqa: SIM115 - closed below, Popen dup'ed it
        else:
            stdout = subprocess.DEVNULL
        try:
            child_env = dict(env) if env is not None else ros_environment()
            self.popen = subprocess.Popen(self.command, env=child_env,
                                          stdout=stdout, stderr=subprocess.STDOUT,
                                          stdin=subprocess.DEVNULL, start_new_session=own_session,
                                          preexec_fn=child_setup(preexec_fn), **text)
        except OSError as exc:
            raise ProcessError(f'cannot start {name}: {exc}') from exc
        finally:
            if log_file is not None:
                log_file.close()

    @property
    def pid(self) -> int:
        return self.popen.pid

    def alive(self) -> bool:
        return self.popen.poll() is None

    def log_tail(self, lines: int = 15) -> str:
        """Return the last ``lines`` lines of the log file ('' without one)."""
        if self.log_path is None or not self.log_path.exists():
            return ''
        return '\n'.join(self.log_path.read_text(errors='replace').splitlines()[-lines:])

    def dump_stacks(self, wait: float = STACK_DUMP_WAIT) -> bool:
        """Ask the process for its threads' stacks in its log (:func:`request_stacks`).

        True when it was sent, and then ``wait`` s have passed for the process to write them.
        """
        return self.alive() and request_stacks(self.pid, wait)

    def signal(self, sig: int) -> None:
        """Send ``sig`` to the process (to its process group when it has its own session)."""
        try:
            if self.own_session:
                os.killpg(self.popen.pid, sig)
            else:
                self.popen.send_signal(sig)
        except ProcessLookupError:
            pass
        except PermissionError:  # pragma: no cover - not our group after all
            self.popen.send_signal(sig)

    def pause(self) -> None:
        """Freeze the process (SIGSTOP): it publishes nothing until :meth:`resume`."""
        self.signal(signal.SIGSTOP)

    def resume(self) -> None:
        self.signal(signal.SIGCONT)

    def stop(self, grace: float = 5.0) -> int:
        """SIGINT (a clean rclpy shutdown), SIGTERM after ``grace`` s, SIGKILL after 2 s more.

        Before SIGTERM and before SIGKILL the process is asked for its Python stacks
        (:meth:`dump_stacks`, in its log): where a process that did not answer was (a
        controller once answered no SIGINT in 5 s and left no line that said why).

        Returns
        -------
        int
            The exit code (negative: the signal that ended it).
        """
        if self.alive():
            self.signal(signal.SIGCONT)        # a paused process cannot handle SIGINT
        for sig, wait in ((signal.SIGINT, grace), (signal.SIGTERM, 2.0), (signal.SIGKILL, 2.0)):
            if not self.alive():
                break
            if sig != signal.SIGINT:
                self.dump_stacks()                   # where it hung, in its log
            self.signal(sig)
            try:
                self.popen.wait(wait)
            except subprocess.TimeoutExpired:
                continue
        return self.popen.wait()

    def __enter__(self) -> 'NodeProcess':
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


@dataclass
class ProcessGroup:
    """Processes that run together and are always stopped together.

    Use as a context manager: on exit (normal, exception or Ctrl-C) every process is
    stopped, in reverse start order, one after another (``one_at_a_time``, the default):
    SIGINT, up to ``grace`` seconds, SIGTERM, SIGKILL (:meth:`NodeProcess.stop`), and the
    next one ``settle`` seconds after the previous one has exited. A participant is then not
    torn down while another one's leaving reaches it: Fast DDS 2.14's ``set_listener``, the
    first step of a participant's deletion, spins for good when a discovery callback is in
    progress (eProsima/Fast-DDS#6513). With ``one_at_a_time``
    False every process gets each signal at once, as ``ros2 launch`` does. Each process runs
    in its own session so that a Ctrl-C at the terminal reaches only the orchestrator, which
    then stops the nodes in order.
    """

    env: dict[str, str]
    log_dir: Path | None = None
    #: Time (s) from SIGINT to SIGTERM. Past the nodes' own teardown limit (4 s,
    #: ``lifetime.TEARDOWN_LIMIT``): a SIGTERM sooner could come while the teardown watch has gdb
    #: on the node and cut its native stacks short.
    grace: float = 5.0
    processes: list[NodeProcess] = field(default_factory=list)
    one_at_a_time: bool = True
    #: Pause (s) after each process has exited, before the next one is signalled and before
    #: ``stop`` returns (the caller may destroy its own nodes next): time for the others to
    #: take its participant's leaving (a few ms on a quiet machine).
    settle: float = 0.1
    #: Process label -> time (s) from its first stop signal to its exit, at the last stop that
    #: found processes running.
    stop_times: dict[str, float] = field(default_factory=dict)

    def start(self, name: str, argv: Sequence[str], *, label: str | None = None,
              rt_priority: int = 0) -> NodeProcess:
        """Start ``argv``; its output goes to ``<log_dir>/<label>.log``.

        ``rt_priority``: as :class:`NodeProcess`.
        """
        label = label or name
        log_path = self.log_dir / f'{label}.log' if self.log_dir is not None else None
        proc = NodeProcess(label, command=argv, env=self.env, log_path=log_path, own_session=True,
                           rt_priority=rt_priority)
        self.processes.append(proc)
        return proc

    def check_alive(self, may_finish: tuple[str, ...] = ()) -> None:
        """Raise :class:`ProcessError` naming any process that has exited.

        Processes named in ``may_finish`` may have exited with code 0.
        """
        for p in self.processes:
            code = p.popen.poll()
            if code is not None and not (code == 0 and p.name in may_finish):
                tail = p.log_tail()
                raise ProcessError(f'{p.name} exited with code {code}'
                                   + (f'; last output:\n{tail}' if tail else ''))

    def stop(self) -> dict[str, int | None]:
        """Stop all processes, in reverse start order: SIGINT, wait, SIGTERM, SIGKILL.

        One after another (``one_at_a_time``) or each signal to all at once. A process still
        running at the SIGTERM or the SIGKILL step is first asked for its stacks
        (:meth:`NodeProcess.dump_stacks`, in its log). :attr:`stop_times` gets each one's time
        from its first signal to its exit.

        Returns
        -------
        dict
            Process label -> exit code.
        """
        running = [p for p in reversed(self.processes) if p.alive()]
        if not running:
            return {p.name: p.popen.poll() for p in self.processes}
        self.stop_times = {}
        if self.one_at_a_time:
            for proc in running:
                began = time.monotonic()
                proc.stop(grace=self.grace)
                self.stop_times[proc.name] = time.monotonic() - began
                time.sleep(self.settle)     # the others (and the caller's own nodes) take its leaving
        else:
            self._stop_together(running)
        return {p.name: p.popen.poll() for p in self.processes}

    def _stop_together(self, running: list[NodeProcess]) -> None:
        """Each signal to every process in ``running`` at once (as ``ros2 launch`` does)."""
        began = time.monotonic()
        for sig, wait in ((signal.SIGINT, self.grace), (signal.SIGTERM, 2.0),
                          (signal.SIGKILL, 2.0)):
            if sig != signal.SIGINT and any([p.dump_stacks(wait=0.0) for p in running]):
                time.sleep(STACK_DUMP_WAIT)          # asked every one: where they hung, in their logs
            for p in running:
                p.signal(sig)
            deadline = time.monotonic() + wait
            while running and time.monotonic() < deadline:
                ended = [p for p in running if not p.alive()]   # asked once: none is missed
                for p in ended:
                    self.stop_times[p.name] = time.monotonic() - began
                running = [p for p in running if p not in ended]
                if running:
                    time.sleep(0.005)
            if not running:
                break

    def __enter__(self) -> 'ProcessGroup':
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


# ---------------------------------------------------------------- domains
def _udp_ports_in_use() -> set[int]:
    try:
        import psutil
        return {c.laddr.port for c in psutil.net_connections(kind='udp') if c.laddr}
    except Exception:  # noqa: BLE001 - psutil missing or not permitted: nothing known
        return set()


def domain_ports(domain_id: int) -> range:
    """Return the DDS port numbers of ``domain_id`` (UDP, and Fast DDS's shared-memory ports)."""
    low = _PORT_BASE + _DOMAIN_GAIN * domain_id
    return range(low, low + _DOMAIN_GAIN)


def domain_in_use(domain_id: int, ports: set[int] | None = None) -> bool:
    """Tell whether some process has bound a DDS port of ``domain_id`` on this machine."""
    ports = _udp_ports_in_use() if ports is None else ports
    own = domain_ports(domain_id)
    return any(p in own for p in ports)


#: Domains the reservations of this process hold (see :func:`held_domains`).
_HELD_HERE: set[int] = set()


def held_domains() -> frozenset[int]:
    """Domains this process holds through :func:`reserve_domains` (e.g. a test suite's own)."""
    return frozenset(_HELD_HERE)


def domain_lock_path(domain_id: int) -> Path:
    """Lock file that marks ``domain_id`` as taken by a run on this machine."""
    return Path(tempfile.gettempdir()) / f'grip_force_ros_domain_{int(domain_id)}.lock'


def _try_lock(domain_id: int):
    """Open file holding an exclusive ``flock`` on the domain's lock file, or None if taken."""
    f = open(domain_lock_path(domain_id), 'a')  # noqa: SIM115 - held until the reservation ends
    try:
        fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        f.close()
        return None
    return f


def domain_locked(domain_id: int) -> bool:
    """Tell whether another run holds the lock of ``domain_id`` (see :func:`reserve_domains`)."""
    f = _try_lock(domain_id)
    if f is None:
        return True
    f.close()          # closing drops our flock again
    return False


def _candidates(start: int | None, candidates: Iterable[int] | None) -> list[int]:
    if candidates is not None:
        return list(candidates)
    first = (os.getpid() % MAX_DOMAIN_ID) + 1 if start is None else start
    return [((first - 1 + k) % MAX_DOMAIN_ID) + 1 for k in range(MAX_DOMAIN_ID)]


def pick_domain_ids(count: int = 1, *, start: int | None = None,
                    candidates: Iterable[int] | None = None,
                    exclude: Iterable[int] = ()) -> list[int]:
    """``count`` ROS domain ids that no process on this machine is using.

    A domain is in use when a process has bound one of its DDS ports, or when a run
    holds its lock (:func:`reserve_domains`). The search starts at a pid-derived id
    (two runs started together rarely pick the same one) and wraps around
    ``1..MAX_DOMAIN_ID``. The ids are not held: a caller that runs nodes for a while
    should hold them with :func:`reserve_domains`.

    Raises
    ------
    ProcessError
        If not enough free domains exist.
    """
    ports = _udp_ports_in_use()
    excluded = set(exclude)
    chosen: list[int] = []
    for d in _candidates(start, candidates):
        if d in excluded or d in chosen or domain_in_use(d, ports) or domain_locked(d):
            continue
        chosen.append(d)
        if len(chosen) == count:
            return chosen
    raise ProcessError(f'no {count} free ROS domain id(s) found')


class DomainReservation:
    """ROS domain ids held by this process: a ``flock`` on each one's lock file.

    Made by :func:`reserve_domains`. Other runs on the machine (test suites, demos,
    benchmarks, each through this module) skip a held domain, so two of them never
    share one; the lock goes with the process (``release``, the end of a ``with``
    block, or the process's exit, whatever way it ends).

    Attributes
    ----------
    ids : list of int
        The domains held, in the order asked.
    """

    def __init__(self, ids: Sequence[int], files: Sequence):
        self.ids = list(ids)
        self._files = list(files)
        _HELD_HERE.update(self.ids)

    @property
    def domain_id(self) -> int:
        """The first (often the only) domain held."""
        return self.ids[0]

    def release(self) -> None:
        """Drop the locks (idempotent)."""
        for f in self._files:
            try:
                fcntl.flock(f, fcntl.LOCK_UN)
            finally:
                f.close()
        if self._files:
            _HELD_HERE.difference_update(self.ids)
        self._files = []

    def __enter__(self) -> 'DomainReservation':
        return self

    def __exit__(self, *exc) -> None:
        self.release()


def reserve_domains(count: int = 1, *, start: int | None = None,
                    candidates: Iterable[int] | None = None,
                    exclude: Iterable[int] = (), retries: int = 3) -> DomainReservation:
    """Find ``count`` free ROS domains and hold them (the one robust way to get a domain).

    Free: no process has bound one of the domain's DDS ports (a port scan, as
    :func:`pick_domain_ids`) and no other run holds its lock file. The lock is taken
    with ``flock(LOCK_EX | LOCK_NB)``, so two runs that scan at the same moment cannot
    both win the same domain; a domain lost that way is skipped and the scan goes on.

    Parameters
    ----------
    count : int
        Number of domains.
    start, candidates, exclude
        As :func:`pick_domain_ids`.
    retries : int
        Scans before giving up (a scan can lose every candidate to concurrent runs).

    Returns
    -------
    DomainReservation

    Raises
    ------
    ProcessError
        If not enough free domains exist.
    """
    excluded = set(exclude)
    held_ids: list[int] = []
    files: list = []
    for _ in range(max(1, retries)):
        ports = _udp_ports_in_use()
        for d in _candidates(start, candidates):
            if d in excluded or d in held_ids or domain_in_use(d, ports):
                continue
            f = _try_lock(d)
            if f is None:
                continue
            held_ids.append(d)
            files.append(f)
            if len(held_ids) == count:
                return DomainReservation(held_ids, files)
    DomainReservation(held_ids, files).release()
    raise ProcessError(f'no {count} free ROS domain id(s) found')
