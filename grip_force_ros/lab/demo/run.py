"""One closed-loop run through real ROS processes: start, record, show, stop, analyse.

:func:`run_task` starts ``sim_instrument``, the controller (or the naive
map) and ``master`` as separate processes on one ROS domain, records every
topic of the interface profile (:class:`~grip_force_ros.lab.demo.messages.RecordedTopics`:
crtk, :data:`grip_force_ros.topics.RECORDED`; or dvrk, the sim playing a dVRK arm) to a
rosbag2 (MCAP), shows
live progress, stops every process (SIGINT, wait, SIGTERM, SIGKILL) whatever
happens, then reads the bag back and computes the figures of
:mod:`grip_force_ros.lab.demo.analysis`.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from grip_force_ros import topics
from grip_force_ros.control import Mode
from grip_force_ros.lab.demo import analysis
from grip_force_ros.lab.demo.messages import RecordedTopics, recorded_topics
from grip_force_ros.lab.processes import (DEFAULT_RT_PRIORITY, NodeProcess, ProcessError,
                                          ProcessGroup, master_rt_priority,
                                          node_command, python_module, realtime_threads,
                                          recorder_rt_priority, ros_args,
                                          ros_environment, ros_tools_environment, wait_until)
from grip_force_ros.params import load_params_file, read_params_yaml
from grip_force_ros.trajectories import MASTER_SPECS, Trajectory, make_trajectory, needle_grasp

#: Seconds the nodes get to start and be discovered before the run is abandoned.
STARTUP_TIMEOUT = 30.0
#: Seconds recorded after the master's trajectory ends.
TAIL = 0.3
#: The master starts held: a needle grasp this slow waits open for minutes. When the
#: controller has the master (DDS discovery of a new process can take seconds on a loaded
#: machine), the real trajectory parameters are set at runtime, which restarts the task.
HOLD_MASTER = {'trajectory': 'needle_grasp', 'trajectory_file': '', 'time_scale': 100.0}
#: Longest wait (s) for the controller to report that it has the master before the task
#: is started anyway (a controller without /diagnostics).
READY_TIMEOUT = 4.0
#: Controller modes (/diagnostics) that mean all its inputs, the master's included, arrive.
READY_MODES = (Mode.FREE, Mode.GRIP)
#: Longest wait (s) for the master's answer to a parameter request before asking it what it
#: holds. An answer can be lost: Fast DDS drops a service reply when the server has not
#: discovered the client's reader 100 ms after the request (rmw_fastrtps #390, #467); on a
#: loaded machine the master took its task and ran it while no answer came. An answer
#: normally takes milliseconds.
ANSWER_WAIT = 2.0
#: Longest wait (s) for one answer: each request unanswered doubles the wait of the next one
#: from :data:`ANSWER_WAIT` up to this (an answer that comes late is taken all the same).
ANSWER_WAIT_MAX = 4.0
#: Most requests (sets and reads) sent to the master to start its task before the run is
#: given up, saying what was waited for (:class:`NoAnswer`).
ANSWER_ATTEMPTS = 8
#: Longest time (s) for the master's parameter service to appear, and again for the whole
#: exchange that starts its task (2 + 7 x 4 s of answer waits: the 8 requests).
MASTER_START_TIMEOUT = 30.0
#: Longest wait (s), once the master's task has ended, for the recorder to take the task's
#: last messages before the nodes are stopped. The recorder runs in this process at normal
#: priority and falls behind on a loaded machine: at load 4.6 on two cores it took the
#: 1 kHz messages up to 4.6 s after they were sent, and stopping the
#: nodes at the task's end lost the steady hold window from the bag. Normally it is
#: milliseconds behind.
RECORDING_CATCH_UP = 20.0


def default_duration() -> float:
    """Length (s) of the needle grasp at time_scale 1."""
    return needle_grasp().duration


@dataclass
class RunSpec:
    """What one run does.

    Attributes
    ----------
    config : Path
        Instrument YAML given to the controller (``--params-file``).
    sim_config : Path or None
        YAML given to the simulated instrument (default: ``config``). The
        compare run gives the sim the YAML as shipped and the controller the
        calibrated one.
    duration : float
        Length of the master's task (s); the needle grasp is time-scaled to it.
    controller : str
        'controller' (the package's node) or 'naive' (current proportional to
        the master closing, :mod:`grip_force_ros.lab.demo.naive_node`).
    controller_overrides, sim_overrides, master_overrides : dict
        ``-p name:=value`` per process.
    label : str
        Name of the run (log files, progress lines).
    interface, arm, master : str
        The nodes' interface profile (``crtk``, or ``dvrk`` with the dVRK arm and master
        names): the sim plays the arm, the master is the dVRK master, the controller asks
        the arm to enable and home (``request_enable``: no console here).
    rt_priority : int
        SCHED_FIFO priority of the two 1 kHz processes (sim and controller) where the
        machine permits it (default :data:`~grip_force_ros.lab.processes.DEFAULT_RT_PRIORITY`,
        as ros2_control's controller manager runs its loop); 0: normal scheduling. The
        master (250 Hz, 0.1 s watchdog) runs ten below it
        (:func:`~grip_force_ros.lab.processes.master_rt_priority`), and the recorder's
        threads, in this process, ten below the master
        (:func:`~grip_force_ros.lab.processes.recorder_rt_priority`).
    namespace : str
        ROS namespace of the run's nodes ('' : the root): one arm of several
        (:func:`run_arms`, ``PSM1``). Its nodes get ``-r __ns:=/<namespace>`` (the crtk
        topics are relative, so they go under it) and ``-r /diagnostics:=/<namespace>/diagnostics``
        (the arms' statuses carry the same names; each arm's recording and analysis read
        its own).
    """

    config: Path
    duration: float = 0.0
    sim_config: Path | None = None
    controller: str = 'controller'
    controller_overrides: dict = field(default_factory=dict)
    sim_overrides: dict = field(default_factory=dict)
    master_overrides: dict = field(default_factory=dict)
    label: str = 'demo'
    interface: str = 'crtk'
    arm: str = 'PSM1'
    master: str = 'MTML'
    rt_priority: int = DEFAULT_RT_PRIORITY
    namespace: str = ''

    def remaps(self) -> dict[str, str]:
        """Return the nodes' remaps of the namespace (none in the root namespace)."""
        ns = self.namespace.strip('/')
        return {'__ns': f'/{ns}', topics.DIAGNOSTICS: f'/{ns}{topics.DIAGNOSTICS}'} if ns else {}

    def profile(self) -> dict[str, Any]:
        """Return the interface parameters every node gets (``-p``)."""
        return {'interface': self.interface, 'arm': self.arm, 'master': self.master}

    def recorded(self) -> RecordedTopics:
        """Return the recorded topics of this run's profile (with the instrument's conversion)."""
        return recorded_topics(load_params_file(self.config, **self.profile()))

    def master_values(self) -> dict[str, Any]:
        """Return the master parameters: schema defaults, then the YAML, then overrides."""
        values = {s.name: s.default for s in MASTER_SPECS}
        try:
            yaml_values = read_params_yaml(self.config)
        except ValueError:
            yaml_values = {}
        values.update({k: v for k, v in yaml_values.items() if k in values})
        values.update(self.master_overrides)
        if values['trajectory'] == 'needle_grasp' and self.duration > 0:
            values['time_scale'] = self.duration / default_duration()
        return values

    def trajectory(self) -> Trajectory:
        v = self.master_values()
        return make_trajectory(v['trajectory'], v['trajectory_file'],
                               master_open_angle=v['master_open_angle'],
                               master_closed_angle=v['master_closed_angle'],
                               time_scale=v['time_scale'])


@dataclass
class RunResult:
    """Outcome of :func:`run_task` (paths, message counts, figures)."""

    spec: RunSpec
    out_dir: Path
    bag: Path
    domain_id: int
    counts: dict[str, int]
    exit_codes: dict[str, int | None]
    trajectory: Trajectory
    data: dict | None = None
    windows: dict | None = None
    metrics: dict | None = None
    plot: Path | None = None
    timing: dict = field(default_factory=dict)
    safe_events: list = field(default_factory=list)
    late_inputs: dict = field(default_factory=dict)
    problems: list = field(default_factory=list)
    scheduling: dict = field(default_factory=dict)
    master_answer: str = ''          # how the master's taking its task was known
    clocks: dict = field(default_factory=dict)   # topic -> the clock of its sample times

    def as_dict(self) -> dict[str, Any]:
        return {
            'label': self.spec.label, 'config': str(self.spec.config),
            'sim_config': str(self.spec.sim_config or self.spec.config),
            'controller': self.spec.controller, 'interface': self.spec.interface,
            'arm': self.spec.arm if self.spec.interface == 'dvrk' else None,
            'master': self.spec.master if self.spec.interface == 'dvrk' else None,
            'controller_overrides': self.spec.controller_overrides,
            'sim_overrides': self.spec.sim_overrides,
            'duration': self.trajectory.duration, 'domain_id': self.domain_id,
            'out_dir': str(self.out_dir), 'bag': str(self.bag),
            'plot': str(self.plot) if self.plot else None,
            'messages': self.counts, 'exit_codes': self.exit_codes,
            'phases': {k: [round(a, 4), round(b, 4)] for k, (a, b) in (self.windows or {}).items()},
            'metrics': self.metrics, 'safe_state_entries': self.safe_events,
            'late_inputs': self.late_inputs, 'scheduling': self.scheduling,
            'master_answer': self.master_answer, 'clocks': self.clocks,
            'problems': self.problems, 'timing': {k: round(v, 3) for k, v in self.timing.items()},
            # one arm of several (run_arms): its namespace
            **({'namespace': '/' + self.spec.namespace.strip('/')} if self.spec.namespace else {}),
        }


def _node_argv(name: str, spec: RunSpec) -> list[str]:
    profile = spec.profile()
    remaps = spec.remaps() or None
    if name == 'master':
        overrides = dict(spec.master_values())
        overrides.update(HOLD_MASTER, exit_when_done=True, **profile)
        return node_command('master', spec.config, overrides, remaps=remaps)
    if name == 'sim_instrument':
        return node_command('sim_instrument', spec.sim_config or spec.config,
                            {**profile, **spec.sim_overrides}, remaps=remaps)
    if spec.controller == 'naive':
        if spec.interface != 'crtk':
            raise ValueError('the naive baseline speaks the crtk profile only')
        return (python_module('grip_force_ros.lab.demo.naive_node')
                + ros_args(spec.config, spec.controller_overrides, node_name='controller',
                           remaps=remaps))
    own = {'request_enable': True} if spec.interface == 'dvrk' else {}
    return node_command('controller', spec.config, {**profile, **own, **spec.controller_overrides},
                        remaps=remaps)


def _poll(predicate: Callable[[], bool], seconds: float, check_alive: Callable[[], None],
          period: float = 0.05) -> bool:
    """Wait up to ``seconds`` for ``predicate()``, calling ``check_alive`` meanwhile; its value."""
    def alive_and_true() -> bool:
        check_alive()
        return predicate()
    return wait_until(alive_and_true, seconds, period)


def _wait_for(predicate: Callable[[], bool], group: ProcessGroup, timeout: float,
              what: str) -> None:
    if not _poll(predicate, timeout, group.check_alive):
        raise ProcessError(f'timed out after {timeout:.0f} s waiting for {what}')


def recording_caught_up(recorder, streams, until: float) -> bool:
    """Tell whether the recorder holds every stream up to ``until`` (s, wall clock).

    True when each of ``streams`` that has been received at all has a message stamped at
    or after ``until`` (the nodes stamp with the system clock). A stream never received
    does not hold the wait: its absence is the analysis's finding, not a lag.
    """
    for stream in streams:
        stamp = recorder.latest_stamp(stream)
        if stamp is not None and stamp < until:
            return False
    return True


def controller_ready(recorder) -> bool:
    """Tell whether the controller's /diagnostics report a mode in :data:`READY_MODES`."""
    from grip_force_ros.lab.demo.messages import diagnostic_summary
    from grip_force_ros.lab.demo.monitor import controller_mode
    item = recorder.latest(topics.DIAGNOSTICS)
    return item is not None and controller_mode(diagnostic_summary(item[1])) in READY_MODES


def _wait_until_ready(recorder, group: ProcessGroup, timeout: float) -> None:
    _poll(lambda: controller_ready(recorder), timeout, group.check_alive)


def _start_master(recorder, spec: RunSpec, group: ProcessGroup, master: NodeProcess,
                  timeout: float = MASTER_START_TIMEOUT) -> str:
    """Start the held master's task now: set its real trajectory parameters at once.

    Returns how the master's taking them was known (see :func:`set_parameters_confirmed`).
    The held master runs its task 100 times slowed (``HOLD_MASTER``), so a clean exit of
    it within ``timeout`` can only follow the task these parameters start: that exit
    counts as the set taken.

    The parameter client is a node of its own in the recorder's context, spun here
    while its answers are awaited: on the recorder's node an answer queues behind the
    recording's backlog (the recorder can fall seconds behind on a loaded machine) and can
    come after every request's wait.

    Raises
    ------
    NoAnswer
        The master answered none of the requests (:func:`set_parameters_confirmed`).
    ProcessError
        The master's parameter service did not appear within ``timeout``, or a node died.
    """
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter_client import AsyncParameterClient

    from grip_force_ros.nodes.lifetime import close_node

    values = spec.master_values()
    ns = spec.namespace.strip('/')
    node = rclpy.create_node('grip_force_demo_parameters', context=recorder.context,
                             namespace=f'/{ns}' if ns else None)
    executor = SingleThreadedExecutor(context=recorder.context)
    executor.add_node(node)
    try:
        client = AsyncParameterClient(node, f'/{ns}/master' if ns else 'master')
        _wait_for(client.services_are_ready, group, timeout, "the master's parameter service")

        def alive() -> None:
            executor.spin_once(timeout_sec=0.0)     # take the answers that came
            group.check_alive(may_finish=('master',))

        outcome = set_parameters_confirmed(
            client, {name: values[name] for name in HOLD_MASTER}, alive, timeout,
            finished=lambda: master.popen.poll() == 0, whom="the master's parameter services")
    finally:
        close_node(executor, node)
    if outcome != 'answered':
        recorder.get_logger().warning(f"the master's answer to its trajectory parameters was "
                                      f'lost: {outcome}')
    return outcome


class NoAnswer(ProcessError):
    """A node answered none of the requests sent to it; the message says what was waited for.

    Attributes
    ----------
    what : str
        What was asked (e.g. setting ['trajectory', ...]).
    whom : str
        Who was asked.
    sets, reads : int
        Requests sent: sets (each would start what the set starts) and reads.
    waited : float
        How long the exchange lasted (s).
    """

    def __init__(self, what: str, whom: str, sets: int, reads: int, waited: float,
                 first_wait: float, last_wait: float):
        self.what, self.whom, self.sets, self.reads, self.waited = what, whom, sets, reads, waited
        super().__init__(
            f'no answer to {what} from {whom}: {sets} set request(s) and {reads} read(s) sent '
            f'over {waited:.1f} s, each answer awaited {first_wait:.1f}-{last_wait:.1f} s '
            '(a late answer to any of them would have been taken)')


def set_parameters_confirmed(client, values: Mapping[str, Any], check_alive: Callable[[], None],
                             timeout: float, answer_wait: float = ANSWER_WAIT,
                             finished: Callable[[], bool] | None = None,
                             attempts: int = ANSWER_ATTEMPTS, whom: str = 'the node',
                             answer_wait_max: float = ANSWER_WAIT_MAX) -> str:
    """Set parameters atomically, and know they were taken even if the answer is lost.

    A set that restarts something (the master's task) must not be sent twice
    blindly: when no answer comes within its wait, the node is asked what it holds
    (a read, safe to repeat, again and again); if it holds ``values`` the set was
    taken and only its answer lost, otherwise the request itself was lost and is sent
    again. Every request stays awaited: a late answer to an earlier set or read
    counts as well as one to the last. Each unanswered request doubles the wait of the
    next, from ``answer_wait`` up to ``answer_wait_max``.

    Parameters
    ----------
    client : rclpy.parameter_client.AsyncParameterClient
        Client of the node (``set_parameters_atomically`` and ``get_parameters``).
    values : mapping
        Parameter name -> value to set.
    check_alive : callable
        Called while waiting; raises if the node's process has died.
    timeout : float
        Longest time for the whole exchange (s).
    answer_wait : float
        Wait for the first answer before asking again (s).
    finished : callable, optional
        True once the node has done what the set starts and exited cleanly (the
        master's task): the set was taken, whatever answer is still missing.
    attempts : int
        Most requests sent, sets and reads together.
    whom : str
        Who is asked (for the error).
    answer_wait_max : float
        Longest wait for one answer (s).

    Returns
    -------
    str
        ``'answered'``; ``'confirmed by a read'`` (the set's answer lost);
        ``'sent again'`` (a request lost, the set sent again and answered or confirmed);
        ``'finished before its answer'`` (``finished`` came true first).

    Raises
    ------
    ProcessError
        The node refused the values (with its reason).
    NoAnswer
        ``attempts`` requests or ``timeout`` passed without any answer that settles it,
        saying what was asked, of whom, how many requests and how long.
    """
    from rclpy.parameter import Parameter, parameter_value_to_python

    names = list(values)
    wanted = [values[name] for name in names]
    done_already = finished or (lambda: False)
    started = time.monotonic()
    deadline = started + timeout
    sets: list = []          # every set request sent (any answer to one settles it)
    reads: list = []         # the reads sent since the last set
    n_reads = 0
    wait = answer_wait

    def send_set() -> None:
        sets.append(client.set_parameters_atomically(
            [Parameter(name, value=values[name]) for name in names]))
        reads.clear()

    def answer_came() -> bool:
        return any(f.done() for f in sets) or any(f.done() for f in reads) or done_already()

    send_set()
    while True:
        _poll(answer_came, max(0.0, min(wait, deadline - time.monotonic())), check_alive,
              period=0.02)
        answered = [f for f in sets if f.done()]
        if answered:
            for future in answered:
                result = future.result().result
                if not result.successful:
                    raise ProcessError(f'the node refused the parameters {names}: '
                                       f'{result.reason}')
            return 'answered' if len(sets) == 1 else 'sent again'
        read = next((f for f in reads if f.done()), None)
        if read is not None:
            held = [parameter_value_to_python(v) for v in read.result().values]
            if held == wanted:
                return 'confirmed by a read' if len(sets) == 1 else 'sent again'
        elif done_already():
            return 'finished before its answer'
        if len(sets) + n_reads >= attempts or time.monotonic() >= deadline:
            break
        if read is not None:        # the node does not hold the values: the set was lost
            send_set()
        else:
            reads.append(client.get_parameters(names))
            n_reads += 1
            wait = min(2.0 * wait, answer_wait_max)
    raise NoAnswer(f'setting {names}', whom, len(sets), n_reads, time.monotonic() - started,
                   answer_wait, wait)


class TaskClock:
    """Where the master is in its task, for the live view.

    Starts from the arrival of the first master sample plus the lead-in, and
    re-synchronises once on the master angle leaving its first value (the
    start of the closing), so that a slow process start does not shift the
    phases shown.
    """

    def __init__(self, trajectory: Trajectory, started: float, threshold: float = 0.02):
        self.trajectory = trajectory
        self.started = started
        tt = np.linspace(0.0, trajectory.duration, max(2, int(trajectory.duration * 1000) + 1))
        aa = trajectory.angle(tt)
        self.first_angle = float(aa[0])
        moved = np.flatnonzero(np.abs(aa - aa[0]) > threshold)
        self.move_time = float(tt[moved[0]]) if moved.size else None
        self.threshold = threshold
        self.synced = self.move_time is None

    def observe(self, master_angle: float, now: float | None = None) -> None:
        """Feed the newest master angle (rad)."""
        if self.synced or not math.isfinite(master_angle):
            return
        if abs(master_angle - self.first_angle) > self.threshold:
            now = time.monotonic() if now is None else now
            self.started = now - self.move_time
            self.synced = True

    def elapsed(self, now: float | None = None) -> float:
        """Seconds since the task started (negative during the lead-in)."""
        return (time.monotonic() if now is None else now) - self.started


def live_status(recorder, trajectory: Trajectory, elapsed: float,
                recorded: RecordedTopics | None = None) -> dict[str, Any]:
    """Return the newest values of the force and state topics, and the task phase."""
    recorded = recorded or RecordedTopics(topics.topic_set('crtk'))
    n = recorded.names
    phase = trajectory.phase(elapsed) if elapsed >= 0 else 'lead-in'
    status: dict[str, Any] = {'t': elapsed, 'phase': phase,
                              'duration': trajectory.duration}
    for topic in (n.master_js, n.target_force, n.estimated_force, n.measured_force, n.command):
        item = recorder.latest(topic)
        if item is not None:
            status.update(recorded.values(topic, item[1]))
    return status


def format_status(s: Mapping[str, Any], label: str = '') -> str:
    """One progress line: phase, time, master angle, target vs measured force, current."""
    def f(key, fmt):
        v = s.get(key)
        return format(v, fmt) if isinstance(v, float) and math.isfinite(v) else '  -  '
    return (f"{label + ' ' if label else ''}[{s.get('phase', '?'):8s} {s.get('t', 0.0):5.2f}/"
            f"{s.get('duration', 0.0):.2f} s] master {f('master_angle', '6.3f')} rad | target "
            f"{f('target_force', '6.3f')} N  measured {f('measured_force', '6.3f')} N  "
            f"estimated {f('estimated_force', '6.3f')} N | current "
            f"{f('current_command', '6.3f')} A")


class Progress:
    """Live progress on a stream: in place on a TTY, plain lines otherwise."""

    def __init__(self, stream=None, label: str = '', every: float = 0.5):
        self.stream = stream
        self.label = label
        self.tty = bool(stream is not None and getattr(stream, 'isatty', lambda: False)())
        self.every = 0.1 if self.tty else every
        self._last = -1e9

    def __call__(self, status: Mapping[str, Any]) -> None:
        if self.stream is None:
            return
        now = time.monotonic()
        if now - self._last < self.every:
            return
        self._last = now
        line = format_status(status, self.label)
        if self.tty:
            self.stream.write('\r\033[K' + line)
        else:
            self.stream.write(line + '\n')
        self.stream.flush()

    def close(self, message: str = '') -> None:
        if self.stream is None:
            return
        if self.tty:
            self.stream.write('\r\033[K')
        if message:
            self.stream.write(message + '\n')
        self.stream.flush()


def run_task(spec: RunSpec, out_dir: str | Path, domain_id: int, *,
             progress: Callable[[Mapping[str, Any]], None] | None = None,
             analyse: bool = True, plot: bool = True,
             startup_timeout: float = STARTUP_TIMEOUT,
             cancelled: Callable[[], bool] | None = None) -> RunResult:
    """Run one task through the real ROS processes and record it.

    Parameters
    ----------
    spec : RunSpec
        Instrument file, task length, label and the nodes' parameter overrides.
    out_dir : path
        New directory for the bag (``bag/``), the node logs (``logs/``) and
        the plot (``summary.png``).
    domain_id : int
        ROS_DOMAIN_ID of the nodes and the recorder.
    progress : callable, optional
        Called about every 0.1 s with :func:`live_status`.
    analyse, plot : bool
        Read the bag back and compute the figures / write the summary plot.
    startup_timeout : float
        Longest wait for the three nodes to publish (s).
    cancelled : callable, optional
        Polled wherever the run waits (every 20-50 ms); when it returns True the run stops
        its nodes and raises KeyboardInterrupt (:func:`run_arms`: a Ctrl-C, or another arm
        that failed).

    Raises
    ------
    ProcessError
        A node failed to start or died during the run.
    """
    import rclpy
    from rclpy.context import Context

    from grip_force_ros.lab.demo.recorder import RecorderNode, SpinThread

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    bag_path = out_dir / 'bag'
    trajectory = spec.trajectory()
    recorded = spec.recorded()
    names = recorded.names
    timing: dict[str, float] = {}
    scheduling: dict[str, str] = {}
    master_answer = ''
    t_begin = time.monotonic()
    # dvrk: the nodes need crtk_msgs, which the sourced ROS tools environment provides
    env = ros_environment(domain_id, base=ros_tools_environment() if spec.interface == 'dvrk'
                          else None)
    context = Context()
    rclpy.init(context=context, domain_id=domain_id)
    recorder = spinner = None
    group = ProcessGroup(env, log_dir=out_dir / 'logs')
    if cancelled is not None:
        check_alive = group.check_alive

        def check_alive_or_cancelled(may_finish: tuple[str, ...] = ()) -> None:
            if cancelled():
                raise KeyboardInterrupt
            check_alive(may_finish)
        group.check_alive = check_alive_or_cancelled
    try:
        # the recorder's threads (DDS receive and events, its executor) under SCHED_FIFO
        # below the master: at normal priority a busy machine starved them past the
        # publishers' KEEP_LAST 10, and the bag lost 100-400 ms of every topic
        with realtime_threads(recorder_rt_priority(spec.rt_priority)) as scheduling['recorder']:
            recorder = RecorderNode(bag_path, topic_types=recorded.types, context=context,
                                    namespace=spec.namespace)
            recorder.subscribe_all()
            spinner = SpinThread(recorder).start()
        with group:
            # all three at once: the master starts held, so nothing happens before it is told
            for name in ('sim_instrument', 'controller'):
                proc = group.start(name, _node_argv(name, spec), rt_priority=spec.rt_priority)
                scheduling[name] = proc.scheduling
            master = group.start('master', _node_argv('master', spec),
                                 rt_priority=master_rt_priority(spec.rt_priority))
            scheduling['master'] = master.scheduling
            # (dvrk: the controller sends its first command once it has enabled the arm)
            needed = [*recorded.state_topics, names.command, names.master_js]
            _wait_for(lambda: all(recorder.count(t) > 0 for t in needed),
                      group, startup_timeout, 'the master, the simulated instrument and the '
                      'controller')
            timing['master_up'] = time.monotonic() - t_begin
            _wait_until_ready(recorder, group, READY_TIMEOUT)
            master_answer = _start_master(recorder, spec, group, master)
            timing['task_start'] = time.monotonic() - t_begin
            clock = TaskClock(trajectory, time.monotonic())
            # the master exits (exit_when_done) shortly after its task: that ends the run
            deadline = clock.started + trajectory.duration + TAIL + startup_timeout
            while master.alive() and time.monotonic() < deadline:
                item = recorder.latest(names.master_js)
                if item is not None:
                    clock.observe(recorded.values(names.master_js, item[1])['master_angle'])
                if progress is not None:
                    progress(live_status(recorder, trajectory, clock.elapsed(), recorded))
                group.check_alive(may_finish=('master',))
                time.sleep(0.05)
            timing['task_end'] = time.monotonic() - t_begin
            # the sim's and the controller's streams go on: wait until the recorder has
            # taken them up to now, so that the bag holds the whole task
            streams = [t for t in recorded.types
                       if t not in (names.master_js, topics.DIAGNOSTICS)]
            task_end_wall = time.time()
            if _poll(lambda: recording_caught_up(recorder, streams, task_end_wall),
                     RECORDING_CATCH_UP, lambda: group.check_alive(may_finish=('master',))):
                timing['recording_caught_up'] = time.monotonic() - t_begin
            exit_codes = group.stop()
            timing['stopped'] = time.monotonic() - t_begin
    finally:
        if spinner is not None:
            spinner.stop()
        counts = {}
        if recorder is not None:
            counts = {t: recorder.count(t) for t in recorded.types}
            recorder.close()
            recorder.destroy_node()
        rclpy.shutdown(context=context)
    result = RunResult(spec, out_dir, bag_path, domain_id, counts, exit_codes, trajectory,
                       timing=timing, scheduling=scheduling, master_answer=master_answer)
    if analyse:
        analyse_run(result, plot=plot)
    timing['total'] = time.monotonic() - t_begin
    return result


def analyse_run(result: RunResult, plot: bool = True) -> RunResult:
    """Read the run's bag back; phases, figures and (optionally) the summary plot.

    Every series, the figures and the plot are on the samples' header stamps
    (:func:`~grip_force_ros.lab.demo.series.read_bag_series`; ``result.clocks`` says, per topic,
    when a topic is on its receive times instead), with one origin: the master's start of
    its task. The plot shows a topic's silences as gaps; the figures interpolate across
    them as before (a run with a silence in its hold is spoiled: ``problems``).
    """
    from grip_force_ros.lab.demo.series import SHOWN_GAP, read_bag_series, resample

    recorded = result.spec.recorded()
    names = recorded.names
    clocks: dict[str, str] = {}
    # one arm of several: its topics are under its namespace
    in_namespace = {'namespace': result.spec.namespace} if result.spec.namespace else {}
    series, diagnostics = read_bag_series(result.bag, recorded, clocks=clocks, **in_namespace)
    result.clocks = clocks
    raw = resample(series, rate=500.0, t0=0.0)
    try:
        start = analysis.trajectory_start(raw['t'], raw['master_angle'], result.trajectory)
    except analysis.AnalysisError:   # the closing was not recorded: first master sample
        ok = np.isfinite(raw['master_angle'])
        if not ok.any():
            raise
        start = float(raw['t'][ok][0])
    data = dict(raw)
    data['t'] = raw['t'] - start
    windows = analysis.phase_windows(result.trajectory, 0.0)
    result.data, result.windows = data, windows
    try:
        result.metrics = analysis.force_metrics(data, windows)
        missing = []
    except analysis.AnalysisError as exc:   # a run the bag does not hold: spoiled, not an error
        result.metrics, missing = {}, [f'{exc}: the recording does not hold the hold phase']
    events = analysis.safe_state_entries(diagnostics, (0.0, result.trajectory.duration), start)
    result.metrics['safe_state_entries'] = len(events)
    result.safe_events = events
    result.late_inputs = analysis.late_inputs(diagnostics, (0.0, result.trajectory.duration), start)
    result.metrics['late_inputs'] = result.late_inputs['total']
    for phase in analysis.MEASURED_PHASES:     # where the figures come from
        if phase in windows:
            result.metrics[f'largest_gap_{phase}'] = max(
                analysis.largest_gap(series[t]['t'] - start, windows[phase])
                for t in (names.target_force, names.measured_force, *recorded.state_topics))
    result.problems = missing + analysis.run_problems({**result.metrics, 'safe_events': events},
                                                      windows)
    if plot:
        from grip_force_ros.lab.demo.plot import summary_plot
        shown = resample(series, rate=500.0, t0=0.0, max_gap=SHOWN_GAP)
        shown['t'] = shown['t'] - start
        where = (f', dvrk {result.spec.arm}/{result.spec.master}' if result.spec.interface == 'dvrk'
                 else f', /{result.spec.namespace.strip("/")}' if result.spec.namespace else '')
        result.plot = summary_plot(shown, windows, result.metrics, result.out_dir / 'summary.png',
                                   title=f'grip-force demo: needle grasp ({result.spec.label}{where})',
                                   clocks=clocks)
    return result


#: A grasp is held when its run is not spoiled (:func:`analysis.run_problems`: no topic silent,
#: no safe-state entry in the hold and pull phases) and its steady-hold error is within these
#: fractions of the target: mean, rms (the end-to-end test's bounds).
HOLD_MEAN_TOLERANCE = 0.10
HOLD_RMS_TOLERANCE = 0.15


def grasp_held(metrics: Mapping[str, Any] | None, problems: list) -> bool:
    """Tell whether a run held its grasp (:data:`HOLD_MEAN_TOLERANCE`, :data:`HOLD_RMS_TOLERANCE`).

    Parameters
    ----------
    metrics : mapping or None
        :func:`analysis.force_metrics` of the run (N; ``target_force``, ``hold_error_mean``,
        ``hold_error_rms``).
    problems : list
        The run's problems (a spoiled run holds nothing).
    """
    m = metrics or {}
    target = m.get('target_force', float('nan'))
    mean, rms = m.get('hold_error_mean', float('nan')), m.get('hold_error_rms', float('nan'))
    if problems or not all(isinstance(v, (int, float)) and math.isfinite(v) for v in (target, mean, rms)):
        return False
    return target > 0 and abs(mean) <= HOLD_MEAN_TOLERANCE * target and rms <= HOLD_RMS_TOLERANCE * target


#: Longest wait (s) for an arm's nodes to publish when several arms start at once: six node
#: processes start, lock and pre-fault their memory together (a master took 10.9 s to do so
#: at load 15 on the two cores, and that arm missed :data:`STARTUP_TIMEOUT`).
ARMS_STARTUP_TIMEOUT = 2 * STARTUP_TIMEOUT


def run_arms(specs: list[RunSpec], out_dir: str | Path, domain_id: int, *,
             progress: Callable[[str], Callable[[Mapping[str, Any]], None] | None] | None = None,
             analyse: bool = True, plot: bool = True,
             startup_timeout: float = ARMS_STARTUP_TIMEOUT) -> dict[str, RunResult]:
    """Run several arms' tasks at once in one ROS domain, each in its own namespace.

    Each spec (its ``namespace`` set, e.g. ``PSM1``, ``PSM2``) is one :func:`run_task` on a
    thread of this process: its own sim, controller and master, its own recorder (a node in
    its namespace recording that namespace's topics into ``<out_dir>/<namespace>/bag``), its
    own analysis and ``summary.png`` in ``<out_dir>/<namespace>/``. A Ctrl-C (or an arm that
    fails) stops every arm's nodes; the first failure is raised after all have stopped.

    Parameters
    ----------
    specs : list of RunSpec
        One per arm, each with a distinct non-empty ``namespace``.
    out_dir : path
        Parent directory of the arms' directories.
    domain_id : int
        ROS_DOMAIN_ID of every arm's nodes and recorders.
    progress : callable, optional
        ``progress(namespace)`` -> that arm's progress callable (or None).
    analyse, plot : bool
        As :func:`run_task`.
    startup_timeout : float
        Longest wait for each arm's three nodes to publish (s; :data:`ARMS_STARTUP_TIMEOUT`).

    Returns
    -------
    dict
        Namespace -> that arm's :class:`RunResult`, in the order of ``specs``.
    """
    import threading

    names = [spec.namespace.strip('/') for spec in specs]
    if not all(names) or len(set(names)) != len(names):
        raise ValueError(f'every arm needs its own namespace, got {names}')
    out_dir = Path(out_dir)
    stop = threading.Event()
    results: dict[str, RunResult] = {}
    errors: dict[str, BaseException] = {}

    def one(spec: RunSpec, name: str) -> None:
        try:
            results[name] = run_task(spec, out_dir / name, domain_id,
                                     progress=progress(name) if progress else None,
                                     analyse=analyse, plot=plot, startup_timeout=startup_timeout,
                                     cancelled=stop.is_set)
        except BaseException as exc:  # noqa: BLE001 - handed to the main thread below
            errors[name] = exc
            stop.set()         # the other arms stop too

    threads = [threading.Thread(target=one, args=(spec, name), name=f'arm-{name}', daemon=True)
               for spec, name in zip(specs, names)]
    for thread in threads:
        thread.start()
    try:
        for thread in threads:
            while thread.is_alive():
                thread.join(timeout=0.1)
    except KeyboardInterrupt:
        stop.set()
        for thread in threads:
            thread.join()
        raise
    first = next(((name, e) for name, e in errors.items() if not isinstance(e, KeyboardInterrupt)),
                 None)
    if first is not None:
        name, exc = first
        if type(exc) is ProcessError:       # say which arm (a NoAnswer keeps its own fields)
            raise ProcessError(f'arm /{name}: {exc}') from exc
        raise exc
    if errors:
        raise next(iter(errors.values()))
    return {name: results[name] for name in names}
