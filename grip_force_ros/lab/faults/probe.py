"""The fault probe: a plant and a fault injector on real DDS topics (rclpy).

:class:`FaultProbe` is an rclpy node that stands in for the master and, by default, the
instrument: at ``rate`` it steps an :class:`~grip_force_ros.sim.InstrumentSim` with the
latest current command it received, publishes the master angle, the joint and actuator
states (and the load cell when asked) over DDS, and passes each sample through the active
fault mutator of its source (:mod:`grip_force_ros.lab.faults.catalogue`). With ``relay`` the
instrument is the shipped ``sim_instrument`` process instead: it publishes its states on
topics under the ``relay`` prefix, and the probe passes each of its messages through the
mutator onto the controller's topics (the commands go from the controller to that process
directly). It records everything the controller publishes (command, target and estimated
force, /diagnostics) and checks every command against the hardware limits as it arrives.
"""
from __future__ import annotations

import bisect
import math
import threading
from collections import deque

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import WrenchStamped
from rclpy.node import Node
from sensor_msgs.msg import JointState

from grip_force_ros import topics
from grip_force_ros.control.inputs import INSTRUMENT_SOURCES, SOURCES
from grip_force_ros.nodes.common import RECORD_QOS, STATE_PUB_QOS, STATE_SUB_QOS, stamp_nanoseconds
from grip_force_ros.sim import InstrumentSim

_TOPICS = {'master': topics.MASTER_JS, 'instrument': topics.INSTRUMENT_JS,
           'actuator': topics.ACTUATOR_JS, 'force': topics.MEASURED_FORCE}


def relay_remaps(prefix: str) -> dict:
    """Topic remaps of a ``sim_instrument`` process whose states the probe relays.

    Its joint, actuator and load-cell topics (and its /diagnostics) go under ``prefix``;
    it still subscribes to the controller's current commands.
    """
    return {**{_TOPICS[s]: f'{prefix}/{_TOPICS[s]}' for s in INSTRUMENT_SOURCES},
            topics.DIAGNOSTICS: f'{prefix}/diagnostics'}


def to_time_msg(seconds: float):
    """Convert float seconds to builtin_interfaces/Time (clamped to its representable range)."""
    from builtin_interfaces.msg import Time
    seconds = min(max(seconds, 0.0), 2.0 ** 31 - 1.0)
    sec = int(math.floor(seconds))
    nanosec = min(int(round((seconds - sec) * 1e9)), 999_999_999)
    return Time(sec=sec, nanosec=nanosec)


#: Slack on the controller's own step time when a slew step is judged (LimitMonitor.resolve),
#: in nominal periods: which step sent a command is known only to within its neighbours
#: (delivery order across two topics), and two commands received as consecutive can be two
#: steps apart. A runaway command is still caught: a missing slew limit jumps 0.5 A at once,
#: which needs a controller step of 4 ms to be allowed. (The exact per-step check, on the
#: controller's own clock, is test/test_control_properties.py.)
DELIVERY_JITTER = 1.0
#: Control steps kept to judge slew steps on (about 2 s at 1 kHz).
STEP_RECORDS = 2000


class LimitMonitor:
    """Checks every current command against |I| <= max_current, |dI| <= slew * dt, finite.

    Parameters
    ----------
    max_current : float
        A.
    max_step : float
        Largest change between consecutive commands one nominal period apart (A) =
        max_current_slew / expected_state_rate.
    period : float, optional
        The nominal period (s). Given, a change beyond ``max_step`` is judged on the
        controller's own step time (:meth:`resolve`, from the steps noted by
        :meth:`note_step`); without it, ``max_step`` is the bound.
    max_period : float
        The longest step time the controller integrates (its watchdog timeout, s): after a
        longer step (a stall) it restarts from the measured current, not bounded.
    """

    def __init__(self, max_current: float, max_step: float, period: float | None = None,
                 max_period: float = math.inf):
        self.max_current = max_current
        self.max_step = max_step
        self.period = period
        self.max_period = max_period
        self.previous: float | None = None
        self.count = 0
        self._violations: list[str] = []
        # the controller's steps as the probe saw them: (receipt s, controller clock s), from
        # the target force each step publishes after its command; and the command steps
        # beyond one period's slew, to be judged on the controller's own step times (resolve)
        self.steps: deque = deque(maxlen=STEP_RECORDS)
        self.pending: list[tuple[float, float, int]] = []   # (receipt s, change A, lost)
        # control steps noted since the last command checked, and the commands this reader
        # missed so far (see resolve)
        self._steps_since_command = 0
        self.commands_missed = 0

    @property
    def violations(self) -> list[str]:
        """Every limit violation so far (slew steps judged on the steps seen by now)."""
        self.resolve(final=True)
        return self._violations

    def note_step(self, t: float, controller_stamp: float) -> None:
        """Record a control step: received at ``t`` (s), the controller's clock at it (s)."""
        self.steps.append((t, controller_stamp))
        self._steps_since_command += 1
        if self.pending:
            self.resolve()

    def resolve(self, final: bool = False) -> None:
        """Judge the pending slew steps on the controller's own step times.

        The controller limits each change to slew times its own measured step time, the
        interval between the stamps of its target forces (its clock at each step). Receipt
        times say little of it: commands queue in this process (the probe shares the
        controller's executor thread; a slow callback, a stall of the process) and arrive
        back to back, or late. The step that sent a command is the one whose target force
        arrives first after it (published right after it); its neighbours are looked at too
        (delivery order across two topics). The longest of these intervals, plus
        :data:`DELIVERY_JITTER` periods, bounds the change; an interval beyond
        ``max_period`` is a stall after which the controller restarts from the measured
        current (not bounded). Commands this reader lost on the way (a stall of its process
        that let the writer's history run over) were steps too: each step publishes its
        command, then its target force, so ``k > 1`` steps received between two commands
        are ``k - 1`` commands lost (counted by :meth:`check`), and the change spans ``k``
        steps. Steps not yet followed by two control steps wait, unless ``final``.

        (Not from rmw's message-lost event, which can deadlock with the rmw_fastrtps of the
        Jazzy wheels, ros2/rmw_fastrtps#890; the message's sequence numbers, the other way,
        do not reach a callback under the EventsExecutor of these wheels.)
        """
        if not self.pending:
            return
        steps = list(self.steps)
        receipts = [r for r, _ in steps]
        still = []
        for t, change, lost in self.pending:
            first = bisect.bisect_left(receipts, t)
            if not final and len(steps) - first < 2:
                still.append((t, change, lost))
                continue
            intervals = [steps[j][1] - steps[j - 1][1] for j in (first - 1, first, first + 1)
                         if 1 <= j < len(steps)]
            longest = max((d for d in intervals if d == d), default=self.period)
            allowed = self.max_step * ((lost + 1) * longest / self.period + DELIVERY_JITTER)
            if longest > self.max_period or abs(change) <= allowed * (1 + 1e-6) + 1e-12:
                continue
            across = f', across {lost} lost commands' if lost else ''
            self._violations.append(
                f'command step {change:+.6f} A beyond the slew limit {allowed:.6f} A over '
                f"the controller's step that sent it {longest * 1e3:.2f} ms{across}")
        self.pending = still

    def check(self, command: float, t: float = math.nan) -> None:
        """Check one command received at ``t`` (s, the probe's clock).

        A change beyond ``max_step`` waits for :meth:`resolve` when the monitor has a
        ``period`` and ``t`` is given; otherwise it is judged against ``max_step`` now.
        """
        self.count += 1
        lost = max(self._steps_since_command - 1, 0) if self.previous is not None else 0
        self._steps_since_command = 0
        self.commands_missed += lost
        why = None
        if not math.isfinite(command):
            why = f'non-finite command {command!r}'
        elif abs(command) > self.max_current * (1 + 1e-9) + 1e-12:
            why = f'command {command:.6f} A above max_current {self.max_current} A'
        elif self.previous is not None and \
                abs(command - self.previous) > self.max_step * (1 + 1e-6) + 1e-12:
            if self.period and t == t:
                self.pending.append((t, command - self.previous, lost))   # judged by resolve
            else:
                why = (f'command step {command - self.previous:+.6f} A beyond the slew limit '
                       f'{self.max_step:.6f} A of one period')
        if why is not None:
            self._violations.append(why)
        self.previous = command if math.isfinite(command) else self.previous


class FaultProbe(Node):
    """Plant + fault injector + recorder (see the module docstring).

    Parameters
    ----------
    params : ParamSet
        The instrument the controller runs (the plant uses the same values).
    rate : float
        Publishing (and plant) rate (Hz).
    sensor : bool
        Also publish the load-cell force.
    master_angle : float
        Master gripper angle held by default (rad); below ``master_contact_angle`` the
        controller grips.
    relay : str, optional
        Topic prefix of a ``sim_instrument`` process (:func:`relay_remaps`): relay its
        states through the fault mutators instead of simulating the instrument here.
    """

    def __init__(self, params, rate: float = 1000.0, sensor: bool = False,
                 master_angle: float = 0.1, relay: str | None = None, **kwargs):
        super().__init__('fault_probe', **kwargs)
        self.params = params
        self.period = 1.0 / rate
        self.sensor = sensor
        self.master_angle = master_angle
        self.relay = relay
        self.plant = InstrumentSim(params, obj=params.object_kind, seed=0)
        self.command = 0.0
        self.lock = threading.RLock()
        # the active fault: source -> mutator, its tick counter and its end event
        self.fault: dict = {}
        self.fault_ticks_left = self.fault_window = 0
        self.fault_k = 0
        self.fault_started = None
        self.fault_applied = 0
        self.fault_done = threading.Event()
        self.restart_pending = False
        self.stamp_offset = {s: 0.0 for s in _TOPICS}   # s, permanent offset (sim clock reset)
        self.last_good_publish = {s: math.nan for s in _TOPICS}  # probe clock of the last good sample
        self._pubs = {}
        for source in SOURCES:
            self._make_pub(source)
        period = 1.0 / params.expected_state_rate
        self.limits = LimitMonitor(params.max_current, params.max_current_slew * period, period,
                                   params.watchdog_timeout)
        self.force_cap = params.max_grip_force
        self.force_violations: list[str] = []
        # records: (probe receive time [s], stamp [s], value); a command's stamp is the
        # actuator state it answers (the probe's clock), the others' the controller's clock
        self.commands: list[tuple] = []
        self.targets: list[tuple] = []
        # one row per control step: (receive time of the target [s], controller stamp [s],
        # current command [A], target force [N]); the controller publishes the command
        # first, and the probe receives both in publishing order, so a target belongs to
        # the command received last before it
        self.steps: list[tuple] = []
        self.estimates: list[tuple] = []
        self.diagnostics: list[tuple] = []   # (receive time, text, values dict)
        self.relayed = 0                     # instrument messages relayed (relay mode)
        if relay is not None:
            for source in INSTRUMENT_SOURCES:
                msg_type = WrenchStamped if source == 'force' else JointState
                self.create_subscription(msg_type, f'{relay}/{_TOPICS[source]}',
                                         lambda msg, s=source: self._on_relayed(s, msg),
                                         STATE_SUB_QOS if source == 'actuator' else RECORD_QOS)
        self.create_subscription(JointState, topics.SERVO_CURRENT, self._on_command, RECORD_QOS)
        self.create_subscription(WrenchStamped, topics.TARGET_FORCE, self._on_target, RECORD_QOS)
        self.create_subscription(WrenchStamped, topics.ESTIMATED_FORCE, self._on_estimate, RECORD_QOS)
        self.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, self._on_diagnostics, RECORD_QOS)
        self.ticks = 0
        self.last_tick = -math.inf          # probe clock of the last tick (s)
        self.timer = self.create_timer(self.period, self._on_timer)

    # ------------------------------------------------------------------ clock
    def now(self) -> float:
        """Probe clock (s), the ROS system clock as the controller's."""
        return self.get_clock().now().nanoseconds * 1e-9

    # ------------------------------------------------------------------ faults
    def inject(self, sources, mutator, ticks: int) -> threading.Event:
        """Apply ``mutator`` to the samples of ``sources`` for ``ticks`` ticks."""
        with self.lock:
            self.fault = {s: mutator for s in sources}
            self.fault_ticks_left = self.fault_window = ticks
            self.fault_k = 0
            self.fault_started = None        # probe clock of the window's first tick (s)
            self.fault_applied = 0           # samples that went through the mutator
            self.fault_done = threading.Event()
            return self.fault_done

    def restart_sim(self, ticks: int, stamp_offset: float = 0.0) -> threading.Event:
        """Restart the simulated instrument as a process restart would look on DDS.

        Destroy the instrument publishers, stay silent ``ticks`` ticks, reset the plant,
        publish again from new publishers (stamps shifted by ``stamp_offset`` s from then on).
        """
        with self.lock:
            self.restart_pending = True
            self.restart_offset = stamp_offset
            return self.inject(('instrument', 'actuator'), lambda s, k: [], ticks)

    def _make_pub(self, source: str) -> None:
        msg_type = WrenchStamped if source == 'force' else JointState
        self._pubs[source] = self.create_publisher(msg_type, _TOPICS[source], STATE_PUB_QOS)

    # ------------------------------------------------------------------ tick
    def samples(self, now: float) -> dict:
        """Return the good samples of this tick (plain dicts) from the plant."""
        m = self.plant.measure()
        return {
            'master': {'stamp': now, 'name': [topics.MASTER_JOINT],
                       'position': [self.master_angle], 'velocity': [0.0], 'effort': []},
            'instrument': {'stamp': now, 'name': [topics.WRIST_JOINT, topics.JAW_JOINT],
                           'position': [m.wrist_angle, m.jaw_angle],
                           'velocity': [0.0, m.jaw_velocity], 'effort': []},
            'actuator': {'stamp': now, 'name': [topics.DRUM_JOINT], 'position': [m.motor_angle],
                         'velocity': [m.motor_velocity], 'effort': [m.current]},
            'force': {'stamp': now, 'force': m.grip_force},
        }

    def _on_timer(self) -> None:
        if self.relay is not None and self.now() - self.last_tick < 0.5 * self.period:
            return                          # a relayed state has just run this tick
        self._tick()

    def _tick(self) -> None:
        self.ticks += 1
        if self.relay is None:
            self.plant.step(self.command, self.period)
        now = self.last_tick = self.now()
        samples = self.samples(now)
        with self.lock:
            fault = self.fault
            k = self.fault_k
            if fault:
                if self.relay is not None:
                    # the sim process runs in real time: the window is wall time, not ticks
                    # (the probe's timer runs late on a loaded machine)
                    if self.fault_started is None:
                        self.fault_started = now
                    k = int((now - self.fault_started) / self.period + 1e-6)
                    self.fault_k = k + 1
                    # and a one-sample fault must have met a sample of the process
                    met = self.fault_applied > 0 or self.restart_pending
                    ended = k + 1 >= self.fault_window and met
                else:
                    self.fault_k += 1
                    self.fault_ticks_left -= 1
                    ended = self.fault_ticks_left <= 0
                if ended:
                    self.fault = {}
                    if self.restart_pending:
                        self._finish_restart()
                    self.fault_done.set()
            elif self.restart_pending:   # pragma: no cover - restart without a window
                self._finish_restart()
        if fault and self.restart_pending and k == 0 and self.relay is None:
            for source in ('instrument', 'actuator'):
                self.destroy_publisher(self._pubs.pop(source))
        for source, sample in samples.items():
            if source == 'force' and not self.sensor:
                continue
            if source not in self._pubs or (self.relay is not None and source in INSTRUMENT_SOURCES):
                continue
            self._pass(source, sample, fault, k, now)

    def _pass(self, source: str, sample: dict, fault: dict, k: int, now: float) -> None:
        """Publish one good sample of ``source`` through the active fault's mutator."""
        sample['stamp'] += self.stamp_offset[source]
        mutate = fault.get(source) or fault.get('all')
        out = [sample] if mutate is None else mutate(sample, k)
        if mutate is None:
            self.last_good_publish[source] = now
        else:
            self.fault_applied += 1
        pub = self._pubs[source]
        msg = shape = None
        for s in out:
            # the samples of a burst or of duplicates differ in their stamp only: build the
            # message once and restamp it (building one costs as much as publishing it, and
            # this process also runs the controller under test)
            fields = {k: v for k, v in s.items() if k != 'stamp'}
            if msg is None or fields != shape:
                msg, shape = self._message(source, s), fields
            else:
                msg.header.stamp = to_time_msg(s['stamp'])
            pub.publish(msg)

    def _on_relayed(self, source: str, msg) -> None:
        """Pass a state of the ``sim_instrument`` process on to the controller, through the fault."""
        if source == 'force' and not self.sensor:
            return
        if self.now() - self.last_tick >= self.period:
            # the timer is late: its event waits behind this process's own messages (a burst
            # relayed to the controller here); the master stream and the fault window must
            # not starve with it (a real master console is a process of its own)
            self._tick()
        with self.lock:
            fault, k = self.fault, self.fault_k
        self.relayed += 1
        if not (fault.get(source) or fault.get('all')) and not self.stamp_offset[source]:
            self.last_good_publish[source] = self.now()   # untouched: the message itself
            self._pubs[source].publish(msg)
            return
        self._pass(source, self._sample(source, msg), fault, k, self.now())

    @staticmethod
    def _sample(source: str, msg) -> dict:
        """Turn a received message into the plain sample dict of the mutators."""
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        if source == 'force':
            return {'stamp': stamp, 'force': msg.wrench.force.z}
        return {'stamp': stamp, 'name': list(msg.name), 'position': list(msg.position),
                'velocity': list(msg.velocity), 'effort': list(msg.effort)}

    def _finish_restart(self) -> None:
        self.restart_pending = False
        if self.relay is None:
            self.plant = InstrumentSim(self.params, obj=self.params.object_kind, seed=1)
        self.command = 0.0
        for source in ('instrument', 'actuator'):
            self.stamp_offset[source] += self.restart_offset
            if source not in self._pubs:
                self._make_pub(source)

    @staticmethod
    def _message(source: str, s: dict):
        if source == 'force':
            msg = WrenchStamped()
            msg.header.stamp = to_time_msg(s['stamp'])
            msg.header.frame_id = topics.JAW_FRAME
            msg.wrench.force.z = float(s['force'])
            return msg
        msg = JointState()
        msg.header.stamp = to_time_msg(s['stamp'])
        msg.name = list(s['name'])
        msg.position = [float(v) for v in s['position']]
        msg.velocity = [float(v) for v in s['velocity']]
        msg.effort = [float(v) for v in s['effort']]
        return msg

    # ------------------------------------------------------------------ records
    @staticmethod
    def _stamp(msg) -> float:
        """Header stamp (s) as the controller computes its clock: integer ns x 1e-9.

        ``sec + nanosec * 1e-9`` differs from it by one ulp (0.24 us at today's epoch) for
        about half of all stamps, enough to put a step the controller saw after a timeout
        before it (fresh-clone CI, a master watchdog case: "period 0 after the timeout").
        """
        return stamp_nanoseconds(msg.header.stamp) * 1e-9

    def _on_command(self, msg: JointState) -> None:
        value = float(msg.effort[0]) if len(msg.effort) else math.nan
        self.command = value if math.isfinite(value) else 0.0
        self.limits.check(value, self.now())
        self.commands.append((self.now(), self._stamp(msg), value))

    def _on_target(self, msg: WrenchStamped) -> None:
        f = msg.wrench.force.z
        if not (math.isfinite(f) and f <= self.force_cap * (1 + 1e-9) + 1e-12):
            self.force_violations.append(f'target force {f!r} N above max_grip_force {self.force_cap} N')
        now, stamp = self.now(), self._stamp(msg)
        self.limits.note_step(now, stamp)
        self.targets.append((now, stamp, f))
        if self.commands:
            self.steps.append((now, stamp, self.commands[-1][2], f))

    def _on_estimate(self, msg: WrenchStamped) -> None:
        self.estimates.append((self.now(), self._stamp(msg), msg.wrench.force.z))

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        now = self.now()
        for status in msg.status:
            values = {kv.key: kv.value for kv in status.values}
            # the current state only: cumulative counters of past rejections stay out
            text = ' | '.join([status.name, status.message] +
                              [f'{k}={v}' for k, v in values.items()
                               if not k.startswith('rejected')])   # 'rejected: <reason>' = count
            self.diagnostics.append((now, text, values, status.level))

    def clear_records(self) -> None:
        """Forget what was recorded so far (the limit monitor keeps counting)."""
        self.commands, self.targets, self.estimates, self.diagnostics = [], [], [], []
        self.steps = []
