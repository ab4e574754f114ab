"""Fault cases of the dVRK interface and the drive, on real node processes.

Each case starts ``sim_instrument``, ``controller`` and ``master`` as processes
(:class:`~grip_force_ros.lab.processes.NodeProcess`; the dvrk profile in the sourced ROS
tools environment, for crtk_msgs) on a free ROS domain, brings the loop into a grasp (the
master held closed), injects the fault and watches the sim's published states and the
nodes' /diagnostics from a probe node in this process:

``controller_sigkill_crtk`` / ``controller_sigkill_dvrk``
    the controller process is killed (SIGKILL) mid-grasp: every state the sim measured from
    35 ms after the kill on carries no current (|I| below 5 std of its noise), the sim's
    drive having cut it after its 30 ms command timeout.
``arm_disabled_mid_grasp``
    the arm is disabled (``state_command`` 'disable', as the dVRK console does): the
    controller goes safe naming the arm's state, sends no more ``jaw/servo_jf``, the
    disabled arm carries no current, and the controller does not enable it again.
``current_on_effort_topic``
    a current-sized number (0.3, a grip current in A) on ``jaw/servo_jf`` of an enabled arm:
    refused by the tool's effort limit (0.16 N*m here), the current stays 0.
``dvrk_master_silent``
    the master (``MTML/gripper/measured_js``) stops (SIGSTOP) mid-grasp: the controller goes
    safe with the stale master within the watchdog timeout plus two state periods, the
    command ramps to 0, and the grasp resumes when the master comes back.
"""
from __future__ import annotations

import math
import re
import shutil
import signal
import subprocess
import threading
import time
from pathlib import Path

from grip_force_ros import topics
from grip_force_ros.control.inputs import source_timeouts
from grip_force_ros.lab.faults.catalogue import FaultCase, redo_spoiled
from grip_force_ros.lab.processes import (DEFAULT_RT_PRIORITY, NodeProcess, ProcessError, node_command,
                                          master_rt_priority, pick_domain_ids, ros_environment,
                                          ros_tools_environment)
from grip_force_ros.params import load_params_file

#: The stamp of a ROS console line: ``[WARN] [1795635733.669077292] [sim_instrument]: ...``.
LOG_STAMP = re.compile(r'\[[A-Z]+\] \[([0-9]+\.[0-9]+)\]')
#: How long after a SIGKILL of the controller the sim's current must be 0 (s): the drive's
#: 30 ms command timeout, its 1 ms check, the 0.2 ms current loop, and 3.8 ms of slack.
KILL_TO_ZERO = 0.035
#: When the sim's 1 ms check must see the 30 ms timeout at the latest (s after the last
#: command); a later check is its process's scheduling, measured and reported.
COMMAND_CHECK_DUE = 0.031
#: A check later than this (s) is a fault, not the machine, unless the sim says its own
#: process was not scheduled for that long (within :data:`STARVED_SLACK`): a stalled
#: machine, the trial spoiled and redone (:func:`run_process_case_redoing_spoiled`).
MAX_CHECK_LATE = 0.1
#: How much of a late check (s) the sim's own starvation may leave unexplained.
STARVED_SLACK = 0.02
#: The sim's cut line: its silence (ms), the current it held until the cut (A), and the
#: starvation it reports before the check (ms).
SIM_CUT = re.compile(r'no command for (?P<silence>[0-9.]+) ms .*drive current cut'
                     r'(?: from (?P<held>-?[0-9.]+) A)?'
                     r'(?:.*not scheduled for (?P<starved>[0-9.]+) ms)?')
#: Longest wait (s) for a sim state past KILL_TO_ZERO after the kill, or past SILENT_TO_ZERO
#: after the master went silent (a starved machine).
KILL_STATE_WAIT = 5.0
#: From the master's silence to a current of 0 A (s): its 100 ms watchdog, the /diagnostics
#: period and the safe ramp, with room for a loaded machine.
SILENT_TO_ZERO = 0.4
#: Longest wait (s) after the master went silent for a safe /diagnostics status that names
#: it: its 100 ms watchdog and a 10 Hz /diagnostics period, with room for a starved probe
#: (receipt gaps of 0.33-0.5 s on a loaded machine).
MASTER_NAMED_WAIT = 2.0
#: |current| below this many standard deviations of the sim's current noise counts as 0 A.
ZERO_NOISE_STD = 5.0
#: How long (s) the ros2 CLI that sends a state command stays up after publishing it, so
#: that the reliable message is delivered on a loaded machine (its default: 0.1 s).
STATE_COMMAND_KEEP_ALIVE = 1.0
#: Longest wait for the loop to grip before a case starts (s; process start and discovery).
READY_TIMEOUT = 40.0
#: Slack on a controller's reaction for DDS delivery and scheduling on a loaded machine (s).
REACTION_SLACK = 0.05
#: Longest wait (s) for the sim's /diagnostics (1 Hz) to count what it refused.
SIM_DIAGNOSTICS_WAIT = 5.0


class _Probe:
    """Records the sim's states, the commands and /diagnostics in this process (rclpy)."""

    def __init__(self, names: topics.TopicSet, conversion, domain_id: int):
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.context import Context
        from sensor_msgs.msg import JointState

        from grip_force_ros.nodes.common import RECORD_QOS, make_executor, stamp_seconds
        from grip_force_ros.lab.harness import SPIN_SLICE
        self._slice = SPIN_SLICE
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node('fault_probe', context=self.context)
        self.lock = threading.Lock()
        self.states: list[tuple[float, float]] = []       # (stamp s, measured current A)
        self.commands: list[float] = []                    # receive times (s)
        self.diagnostics: list[tuple[float, dict]] = []    # (receive s, status)
        effort = names.interface == 'dvrk'
        joint = topics.JAW_JOINT if effort else topics.DRUM_JOINT

        def on_state(msg):
            if joint in msg.name:
                value = msg.effort[list(msg.name).index(joint)]
                current = conversion.current(value) if effort else value
                with self.lock:
                    self.states.append((stamp_seconds(msg.header.stamp), current))

        def on_command(_msg):
            with self.lock:
                self.commands.append(time.time())

        def on_diag(msg):
            now = time.time()
            statuses = [{'name': s.name, 'values': {kv.key: kv.value for kv in s.values}}
                        for s in msg.status]
            with self.lock:
                self.diagnostics += [(now, s) for s in statuses]

        # the drum's current: dvrk in the jaw's state; crtk in the sim's combined state
        state_topic = names.actuator_js if effort else names.instrument_js
        self.node.create_subscription(JointState, state_topic, on_state, RECORD_QOS)
        self.node.create_subscription(JointState, names.command, on_command, RECORD_QOS)
        self.node.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, on_diag, RECORD_QOS)
        self.publisher = self.node.create_publisher(JointState, names.command, RECORD_QOS)
        # the EventsExecutor: ~45 us of CPU per message against ~130 us for rclpy's
        # SingleThreadedExecutor (lab/demo/recorder.py SpinThread). A probe that falls more than
        # its reader's depth (1000 states, 1 s) behind loses the oldest states: the kill's
        self.executor = make_executor(context=self.context)
        self.executor.add_node(self.node)
        self._stop = False
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self):
        while not self._stop and self.context.ok():
            # short slices: the EventsExecutor holds the GIL while it waits
            self.executor.spin_once(timeout_sec=self._slice)

    def latest(self, name_part: str) -> dict | None:
        """Return the newest diagnostic status whose name contains ``name_part``."""
        with self.lock:
            for _, status in reversed(self.diagnostics):
                if name_part in status['name']:
                    return status
        return None

    def diagnostics_gap_since(self, start: float) -> float:
        """Longest gap (s) between /diagnostics receipts from ``start`` (time.time()) to now."""
        with self.lock:
            times = [start] + [t for t, _ in self.diagnostics if t > start] + [time.time()]
        return round(max(b - a for a, b in zip(times, times[1:])), 3)

    def wait(self, predicate, timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if predicate():
                return True
            time.sleep(0.02)
        return False

    def close(self):
        from grip_force_ros.nodes.lifetime import close_node, shutdown_once
        self._stop = True
        self._thread.join(timeout=2.0)
        close_node(self.executor, self.node)   # the executor first: see close_node
        shutdown_once(self.context)


#: The sim's measured current (A) that counts as holding a grip (the hold needs ~0.12-0.3 A).
GRIP_CURRENT = 0.05


def _gripping(probe: _Probe) -> bool:
    """Tell whether the controller grips and the sim's last states carry the grip current."""
    status = probe.latest('controller')
    with probe.lock:
        recent = [i for _, i in probe.states[-5:]]
    return status is not None and status['values'].get('mode') == 'grip' and \
        float(status['values'].get('current_command_A', 0.0)) > GRIP_CURRENT and \
        len(recent) == 5 and min(recent) > GRIP_CURRENT


class _Loop:
    """sim + controller + master processes of one profile, the probe, a log directory."""

    def __init__(self, config: Path, interface: str, log_dir: Path):
        self.interface = interface
        params = load_params_file(config, interface=interface)
        self.params = params
        self.names = topics.topic_set(interface, params.arm, params.master)
        from grip_force_ros.model.dvrk_jaw import JawEffortConversion
        self.conversion = JawEffortConversion.from_params(params)
        self.domain = pick_domain_ids(1)[0]
        base = ros_tools_environment() if interface == 'dvrk' else None
        self.env = ros_environment(self.domain, base=base)
        self.log_dir = log_dir
        log_dir.mkdir(parents=True, exist_ok=True)
        profile = {'interface': interface}
        held = {'master_open_angle': 0.0, 'master_closed_angle': 0.0, **profile}   # closed: grip
        self.procs = {}
        self.probe = _Probe(self.names, self.conversion, self.domain)
        try:
            for name, extra in (('sim_instrument', profile),
                                ('controller', {**profile, 'request_enable': interface == 'dvrk'}),
                                ('master', held)):
                # the 1 kHz processes as the demo runs them (docs/demo.md): SCHED_FIFO where
                # permitted; the sim is the drive's stand-in, whose 30 ms cut a starved
                # process would make late (0.19 A past 35 ms at load 6)
                self.procs[name] = NodeProcess(
                    name, command=node_command(name, config, extra), env=self.env,
                    log_path=log_dir / f'{name}.log',
                    rt_priority=(DEFAULT_RT_PRIORITY if name != 'master'
                                 else master_rt_priority(DEFAULT_RT_PRIORITY)))
        except ProcessError:
            self.close()
            raise

    def log(self, name: str, since: float = -math.inf) -> str:
        """Read the log of process ``name``, from its first line stamped at or after ``since``."""
        return lines_since((self.log_dir / f'{name}.log').read_text(errors='replace'), since)

    def state_command(self, command: str) -> bool:
        """Send a crtk state command to the arm with the ros2 CLI (crtk_msgs, sourced env).

        The CLI stays up for STATE_COMMAND_KEEP_ALIVE after publishing: with the default
        0.1 s the disable may never reach the sim on a loaded machine, and the case would
        fail as if the controller had ignored a disabled arm.
        """
        ros2 = shutil.which('ros2', path=self.env.get('PATH')) or 'ros2'
        done = subprocess.run([ros2, 'topic', 'pub', '--once', '-w', '1',
                               '--keep-alive', str(STATE_COMMAND_KEEP_ALIVE),
                               '/' + self.names.state_command, 'crtk_msgs/msg/StringStamped',
                               f'{{string: {command}}}'],
                              env=self.env, capture_output=True, text=True, timeout=60)
        return done.returncode == 0

    def close(self):
        for proc in reversed(list(self.procs.values())):
            proc.stop()
        self.probe.close()


def lines_since(text: str, since: float) -> str:
    """Keep the lines of a ROS console log stamped at or after ``since`` (s, wall clock).

    A line is ``[LEVEL] [stamp] [node]: text`` (stamp = the ROS system clock, as
    ``time.time()``); a line without a stamp goes with the stamped line before it.
    """
    kept, keep = [], since == -math.inf
    for line in text.splitlines():
        stamp = LOG_STAMP.match(line)
        if stamp:
            keep = float(stamp.group(1)) >= since
        if keep:
            kept.append(line)
    return '\n'.join(kept)


def _zero_current(loop: _Loop) -> float:
    return ZERO_NOISE_STD * loop.params.current_noise_std


def _kill_case(loop: _Loop, detail: dict) -> list[str]:
    problems = []
    if not loop.probe.wait(lambda: _gripping(loop.probe), 5.0):
        return ['not gripping before the kill']
    kill = time.time()
    loop.procs['controller'].signal(signal.SIGKILL)
    time.sleep(0.5)
    zero = _zero_current(loop)
    # on a starved machine the sim's states (or the probe taking them) can lag the kill by
    # more than the first 0.5 s: wait for a state past the bound, up to KILL_STATE_WAIT
    deadline = time.monotonic() + KILL_STATE_WAIT
    while True:
        with loop.probe.lock:
            after = [(t, i) for t, i in loop.probe.states if t >= kill]
        first_zero = next((t for t, i in after if abs(i) < zero), math.nan)
        # The drive's timeout runs from the last command that reached it, which may arrive
        # after the kill (in flight, or queued in the sim's executor on a busy machine:
        # 35.4-36.7 ms from the kill at load 2-3, 30.5 ms quiet). The sim says how long it
        # had been without a command when it cut; the bound runs from the later of the kill
        # and that arrival.
        # the cut after the kill (the sim may also have cut at start-up, before the
        # controller's commands flowed: 'no command for 334.5 ms ... from 0.0000 A')
        silence = SIM_CUT.search(loop.log('sim_instrument', kill))
        arrival = first_zero - float(silence['silence']) * 1e-3 if silence else kill
        start = max(kill, arrival)
        # the sim's own check of the timeout can run late when its process is not scheduled
        # (a firmware drive's would not): that lateness, which the sim measures, is the
        # machine's and is reported; the cut itself must then hold within the bound
        check_late = (max(0.0, float(silence['silence']) * 1e-3 - COMMAND_CHECK_DUE)
                      if silence else 0.0)
        late = [(t, i) for t, i in after if t >= start + KILL_TO_ZERO + check_late]
        if late or time.monotonic() > deadline:
            break
        time.sleep(0.05)
    detail['last_command_after_kill_ms'] = round(max(0.0, arrival - kill) * 1e3, 1)
    detail['sim_check_late_ms'] = round(check_late * 1e3, 1)
    starved = float(silence['starved']) * 1e-3 if silence and silence['starved'] else 0.0
    detail['sim_not_scheduled_ms'] = round(starved * 1e3, 1)
    if check_late > MAX_CHECK_LATE and starved >= check_late - STARVED_SLACK:
        detail['spoiled'] = (f"the sim's timeout check came {check_late * 1e3:.0f} ms late: its "
                             f'process was not scheduled for {starved * 1e3:.0f} ms (the machine)')
        return [detail['spoiled']]
    if check_late > MAX_CHECK_LATE:
        problems.append(f"the sim's timeout check came {check_late * 1e3:.0f} ms late")
    if not late:
        return [f'no sim state after the kill (waited {KILL_STATE_WAIT:g} s)']
    # what the drive carried when the commands stopped: the sim's own word in its cut line.
    # The probe's first state after the kill is only a second witness: a probe process
    # lagging more than its reader's depth (RECORD_QOS, 1000 states = 1 s) loses the
    # oldest states, which are those of the kill (fresh-clone CI of 5a4330b: the sim cut
    # from 0.2437 A after the kill, the probe's first state after it read ~0 A)
    detail['current_at_kill_A'] = round(after[0][1], 4) if after else None
    detail['probe_first_state_after_kill_ms'] = round((after[0][0] - kill) * 1e3, 1) \
        if after else None
    held = float(silence['held']) if silence and silence['held'] else None
    detail['current_held_until_cut_A'] = held
    carried = held if held is not None else (after[0][1] if after else 0.0)
    if carried < GRIP_CURRENT:
        problems.append('the sim carried no grip current at the kill')
    detail['current_zero_after_ms'] = round((first_zero - kill) * 1e3, 1)
    detail['current_zero_after_last_command_ms'] = round((first_zero - start) * 1e3, 1)
    detail['largest_current_35ms_after_A'] = round(max(abs(i) for _, i in late), 4)
    if max(abs(i) for _, i in late) >= zero:
        problems.append(f'current {max(abs(i) for _, i in late):.4f} A at or after '
                        f'{KILL_TO_ZERO * 1e3:g} ms from the kill or the last command')
    if not re.search(r'no command for .* drive current cut', loop.log('sim_instrument', kill)):
        problems.append('the sim did not report the command timeout')
    return problems


def _safe_naming(loop: _Loop, reason_part: str = '') -> bool:
    """Tell whether the controller's newest status is safe with ``reason_part`` in its reasons."""
    status = loop.probe.latest('controller')
    return (status is not None and status['values'].get('mode') == 'safe'
            and reason_part in status['values'].get('reasons', ''))


def _disable_case(loop: _Loop, detail: dict) -> list[str]:
    problems = []
    if not loop.state_command('disable'):
        return ['ros2 topic pub of the disable failed']
    sent = time.time()
    safe = loop.probe.wait(lambda: _safe_naming(loop, 'DISABLED'), 5.0)
    if not safe:
        problems.append('the controller did not go safe naming the DISABLED arm')
    time.sleep(1.5)
    with loop.probe.lock:
        late_commands = [t for t in loop.probe.commands if t > sent + 0.2]
        late_states = [i for t, i in loop.probe.states if t > sent + 0.2]
    detail['servo_jf_after_disable'] = len(late_commands)
    detail['largest_current_after_disable_A'] = round(max(map(abs, late_states)), 4) \
        if late_states else None
    if late_commands:
        problems.append(f'{len(late_commands)} jaw/servo_jf sent to the disabled arm')
    if not late_states or max(map(abs, late_states)) >= _zero_current(loop):
        problems.append('the disabled arm carries current')
    status = loop.probe.latest('controller')
    if status is None or status['values'].get('arm_state') != 'DISABLED':
        problems.append('the controller enabled the arm again (or lost its state)')
    detail['reason'] = status['values'].get('reasons') if status else None
    return problems


def _units_case(loop: _Loop, detail: dict) -> list[str]:
    from sensor_msgs.msg import JointState
    problems = []
    loop.procs['controller'].stop()          # nobody else commands the jaw
    time.sleep(0.3)
    before = len(loop.probe.states)
    msg = JointState(name=[topics.JAW_JOINT], effort=[0.3])
    start = time.time()
    for _ in range(50):                      # 0.5 s at the dVRK's 100 Hz
        msg.header.stamp = loop.probe.node.get_clock().now().to_msg()
        loop.probe.publisher.publish(msg)
        time.sleep(0.01)

    def refused_count() -> int:              # the sim's diagnostics come at 1 Hz
        sim = loop.probe.latest('sim_instrument')
        return int(sim['values'].get('servo_jf_refused_effort_limit', 0)) if sim else 0

    loop.probe.wait(lambda: refused_count() >= 50, SIM_DIAGNOSTICS_WAIT)
    with loop.probe.lock:
        currents = [i for t, i in loop.probe.states[before:] if t > start]
    refused = refused_count()
    detail['refused_by_effort_limit'] = refused
    detail['largest_current_A'] = round(max(map(abs, currents)), 4) if currents else None
    if refused < 40:
        problems.append(f'only {refused} of 50 refused by the effort limit')
    if not currents or max(map(abs, currents)) >= _zero_current(loop):
        problems.append('the current-sized effort drove the jaw')
    if not re.search(r'beyond the tool limit', loop.log('sim_instrument', start)):
        problems.append('no warning in the sim log')
    return problems


def _master_case(loop: _Loop, detail: dict) -> list[str]:
    problems = []
    master = loop.procs['master']
    stopped = time.time()
    master.pause()
    safe = loop.probe.wait(lambda: _safe_naming(loop), 2.0)
    reacted = time.time() - stopped
    first = loop.probe.latest('controller')
    detail['safe_after_s'] = round(reacted, 3)
    detail['reason_when_safe'] = first['values'].get('reasons') if first else None
    # the safe state may come first for another input (a controller or sim stall on a loaded
    # machine); the stale master must be named while it stays silent, by
    # its own watchdog, a step and a /diagnostics period, or later if the probe was starved
    named = loop.probe.wait(lambda: _safe_naming(loop, 'stale master'), MASTER_NAMED_WAIT)
    detail['master_named_after_s'] = round(time.time() - stopped, 3) if named else None
    detail['reason_named'] = loop.probe.latest('controller')['values'].get('reasons') if named else None
    time.sleep(max(0.0, stopped + 0.5 - time.time()))
    status = loop.probe.latest('controller')
    detail['reason'] = status['values'].get('reasons') if status else None
    detail['diagnostics_gap_max_s'] = loop.probe.diagnostics_gap_since(stopped)
    # the master's own watchdog (100 ms, not the instrument's 30 ms), two steps, a
    # /diagnostics period (10 Hz)
    bound = source_timeouts(loop.params)['master'] + 2.0 / loop.params.expected_state_rate + \
        1.0 / 10.0 + REACTION_SLACK
    detail['bound_s'] = round(bound, 3)
    if not safe or reacted > bound:
        problems.append(f'safe after {reacted:.3f} s, bound {bound:.3f} s')
    if not named:
        problems.append(f'no safe status named the stale master within {MASTER_NAMED_WAIT} s '
                        f'(reason when safe: {detail["reason_when_safe"]!r}; '
                        f'at +0.5 s: {detail["reason"]!r})')

    def silent_states() -> list[float]:
        with loop.probe.lock:
            return [i for t, i in loop.probe.states if t > stopped + SILENT_TO_ZERO]
    # on a starved machine the sim's states of that time (or the probe taking them) can come
    # later still: wait for one, as the kill case does, rather than fail as "did not ramp"
    # with no state to tell
    loop.probe.wait(lambda: bool(silent_states()), KILL_STATE_WAIT)
    late = silent_states()
    detail['states_while_silent'] = len(late)
    detail['largest_current_while_silent_A'] = round(max(map(abs, late)), 4) if late else None
    if not late:
        problems.append(f'no instrument state stamped {SILENT_TO_ZERO} s after the master '
                        f'went silent within {KILL_STATE_WAIT} s')
    elif max(map(abs, late)) >= _zero_current(loop):
        problems.append('the current did not ramp to 0')
    if problems:      # the states and commands around the pause, to tell why
        _record_silence(loop, detail, stopped)
    master.resume()
    if not loop.probe.wait(lambda: _gripping(loop.probe), 10.0):
        problems.append('no grip again after the master came back')
    return problems


#: States and commands kept in a failed master case's detail, around the pause (s).
SILENCE_RECORD = (-0.3, 1.5)


def _record_silence(loop: _Loop, detail: dict, stopped: float) -> None:
    """Keep what the probe saw around the master's pause (``stopped``, time.time() s).

    ``states_around_pause``: (stamp - stopped s, measured current A) of every sim state in
    :data:`SILENCE_RECORD`; ``commands_around_pause``: receipt times of the controller's
    commands there (s from the pause); ``sim_log_after_pause``: the sim's lines since (its
    drive cuts, with how long it went unscheduled). A starved sim, a controller that commands
    again, or a probe that lags show apart in them.
    """
    first, last = (stopped + bound for bound in SILENCE_RECORD)
    with loop.probe.lock:
        states = [(round(t - stopped, 4), round(i, 4)) for t, i in loop.probe.states if first <= t <= last]
        commands = [round(t - stopped, 4) for t in loop.probe.commands if first <= t <= last]
    detail['states_around_pause'] = states
    detail['commands_around_pause'] = commands
    detail['sim_log_after_pause'] = loop.log('sim_instrument', stopped)[-2000:]


_RUN = {'controller_sigkill_crtk': ('crtk', _kill_case),
        'controller_sigkill_dvrk': ('dvrk', _kill_case),
        'arm_disabled_mid_grasp': ('dvrk', _disable_case),
        'current_on_effort_topic': ('dvrk', _units_case),
        'dvrk_master_silent': ('dvrk', _master_case)}


def run_process_case(case: FaultCase, config: Path, log_root: Path) -> dict:
    """Run one case of :func:`~grip_force_ros.lab.faults.catalogue.dvrk_cases` on fresh processes.

    Returns the report's detail dict.
    """
    detail = {'name': case.name, 'category': case.category, 'outcome': case.outcome,
              'description': case.description}
    interface, body = _RUN[case.name]
    loop = None
    try:
        loop = _Loop(Path(config), interface, log_root / case.name)
        if not loop.probe.wait(lambda: _gripping(loop.probe), READY_TIMEOUT):
            detail.update(passed=False, why='the loop never gripped before the fault')
            return detail
        time.sleep(0.3)                          # a steady grip
        problems = body(loop, detail)
    except ProcessError as exc:
        problems = [f'processes: {exc}']
    finally:
        if loop is not None:
            crashed = [n for n in loop.procs if 'Traceback' in loop.log(n)]
            loop.close()
            if crashed:
                detail['crash'] = crashed
    if detail.get('crash'):
        problems.append(f"a Python traceback in {detail['crash']}")
    detail['passed'] = not problems
    if problems:
        detail['why'] = '; '.join(problems)
    return detail


def run_process_case_redoing_spoiled(case: FaultCase, config: Path, log_root: Path) -> dict:
    """Run a process case; a trial the machine spoiled is redone, at most twice.

    Spoiled: the sim's own process was not scheduled for most of a late timeout check (it
    says so in its cut line).
    The third spoiled trial fails with its cause. The logs are the last trial's.
    """
    return redo_spoiled(lambda: run_process_case(case, config, log_root), 'a stalled machine')


def run_process_cases(cases: list[FaultCase], config: Path, progress=None) -> list[dict]:
    """Run the process cases one after the other (each on its own ROS domain)."""
    import tempfile
    root = Path(tempfile.mkdtemp(prefix='grip_force_faults_'))
    details = []
    for case in cases:
        detail = run_process_case_redoing_spoiled(case, config, root)
        detail['logs'] = str(root / case.name)
        details.append(detail)
        if progress:
            progress(detail)
    return details


__all__ = ['run_process_case', 'run_process_cases', 'KILL_TO_ZERO']
