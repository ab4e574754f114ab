"""Run the fault catalogue against the real controller node (rclpy, loopback DDS).

* Message, silence and sim-restart faults: the controller node runs in this process
  (``parameter_overrides`` from the instrument YAML), a :class:`FaultProbe` closes the loop
  with a simulated instrument and injects each fault over DDS; one executor thread spins both.
  Every case that involves the instrument runs a second time against the shipped
  ``sim_instrument`` process (plant ``sim_instrument``): its states reach the controller
  through the probe, which applies the fault on the way; "sim restart" kills that process
  and starts a new one.
* Runtime parameter faults: the probe calls the controller's parameter services.
* Parameter-file faults: the ``controller`` executable is started with the bad
  ``--params-file`` and must exit non-zero naming the problem (no traceback).
* Negative control (:mod:`.defects`): each deliberately broken controller build runs the
  cases that must catch it; every defect must make at least one of them fail.

:func:`run_faultcheck` returns the report ``{"cases", "passed", "crashes",
"limit_violations", "failures", "details", "negative_control"}``.
"""
from __future__ import annotations

import math
import os
import re
import subprocess
import sys
import tempfile
import threading
import time
import traceback
from pathlib import Path

from grip_force_ros import topics
from grip_force_ros.control import Mode
from grip_force_ros.control.controller import CONTROLLER_STALLED
from grip_force_ros.control.inputs import INSTRUMENT_SOURCES, source_timeouts
from grip_force_ros.lab.faults.catalogue import (SOURCES, FaultCase, bad_params_text, catalogue,
                                                 redo_spoiled)
from grip_force_ros.lab.processes import STACK_THREAD_HEADER, request_stacks
from grip_force_ros.params import load_params_file, read_params_yaml
from grip_force_ros.params.controller import STATE_RATE_MAX
from grip_force_ros.params.files import instrument_path

#: Default master angle of the probe (rad): below master_contact_angle, so the controller grips.
GRIP_MASTER_ANGLE = 0.1
#: How long a case may take to recover after its fault window (s): ~0.1 s on a quiet machine,
#: more than 2 s on a loaded one (load 11 on 2 cores). Never resuming is the fault.
RECOVERY_TIMEOUT = 10.0
#: Longest wait for the controller to grip before a case starts (s): ~0.1 s on a quiet
#: machine; more than 5 s once at load 8 (never gripping is the fault).
READY_TIMEOUT = 15.0
#: Bumpless resume: the first command after the safe state may differ from the last safe
#: command by at most this share of one slew step.
RESUME_JUMP_SHARE = 0.5
#: Namespace of the controller processes started with bad parameter files.
ISOLATION_NS = '/faultcheck_param_file'
#: Extra allowance on the watchdog latency for DDS delivery and timer jitter (s).
WATCHDOG_SLACK = 0.002
#: The plants a case can run against: the probe's own InstrumentSim, or the shipped
#: ``sim_instrument`` process (relayed through the probe).
PLANTS = ('probe', 'sim_instrument')
#: Topic prefix of the ``sim_instrument`` process's states (the probe relays them).
RELAY_PREFIX = '/faultcheck_sim'
#: Longest wait for a ``sim_instrument`` process to start and the loop to grip (s).
PROCESS_READY_TIMEOUT = 30.0
#: A fault window this short is one bad sample among good ones; it is sent again (at most
#: SINGLE_SAMPLE_ATTEMPTS times in all) until the controller has taken one.
SINGLE_SAMPLE_TICKS = 2
SINGLE_SAMPLE_ATTEMPTS = 5
#: Trials of a defect's cases in the negative control until one catches it: a defect is
#: always there, but a loaded machine can hide one trial of it (a controller step of 4 ms
#: is long enough for the 0.5 A jump of a missing slew limit; see run_negative_control).
DEFECT_TRIALS = 3


def involves_instrument(case: FaultCase) -> bool:
    """Tell whether a case faults the instrument's side (so it runs on the sim process too)."""
    return case.kind in ('message', 'restart') and (
        case.source in INSTRUMENT_SOURCES or case.source in ('all', 'restart'))


# ---------------------------------------------------------------------------- session
class Session:
    """One in-process controller node and a fault probe, spun by one executor thread.

    Parameters
    ----------
    config : Path
        Instrument YAML (its values become the controller's ``parameter_overrides``).
    sensor : bool
        Controller with ``force_sensor_enabled`` and a probe publishing the load cell.
    plant : str
        One of :data:`PLANTS`: the probe's InstrumentSim, or a ``sim_instrument`` process.
    defect : str, optional
        A deliberately broken controller (:mod:`.defects`, negative control only).
    """

    def __init__(self, config: Path, sensor: bool = False, plant: str = 'probe',
                 defect: str | None = None):
        import rclpy
        from rclpy.context import Context
        from rclpy.parameter import Parameter

        from grip_force_ros.lab.faults.probe import FaultProbe
        from grip_force_ros.nodes.common import make_executor
        from grip_force_ros.nodes.controller import ControllerNode
        from grip_force_ros.lab.harness import SPIN_SLICE, freeze_heap

        freeze_heap()     # a full collection of a large process's heap stalls the nodes here
        values = read_params_yaml(config)
        if sensor:
            values['force_sensor_enabled'] = True
        # the probe reads the controller's steps off its target forces (published right
        # after each step's command): one a step, whatever the shipped output rate
        values['force_output_rate'] = STATE_RATE_MAX
        self.params = load_params_file(config, **({'force_sensor_enabled': True} if sensor else {}))
        self.context = Context()
        rclpy.init(context=self.context)
        overrides = [Parameter(k, value=list(v) if isinstance(v, (list, tuple)) else v)
                     for k, v in values.items()]
        self.controller = ControllerNode(parameter_overrides=overrides, context=self.context)
        if defect is not None:
            from grip_force_ros.lab.faults.defects import break_controller
            break_controller(self.controller, defect)
        if plant not in PLANTS:
            raise ValueError(f'unknown plant {plant!r}; one of {PLANTS}')
        self.plant, self.config, self.sim = plant, Path(config), None
        self.ready_timeout = READY_TIMEOUT if plant == 'probe' else PROCESS_READY_TIMEOUT
        self.recovery_timeout = RECOVERY_TIMEOUT
        self.probe = FaultProbe(self.params, rate=self.params.control_rate, sensor=sensor,
                                master_angle=GRIP_MASTER_ANGLE, context=self.context,
                                relay=RELAY_PREFIX if plant == 'sim_instrument' else None)
        if plant == 'sim_instrument':
            self.sim = self._start_sim()
        self.executor = make_executor(self.context)
        self._slice = SPIN_SLICE
        self.executor.add_node(self.controller)
        self.executor.add_node(self.probe)
        self.crash: str | None = None
        self._stop = False
        self._thread = threading.Thread(target=self._spin, name='faultcheck-spin', daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        try:
            while not self._stop and self.context.ok():
                # short slices: the EventsExecutor holds the GIL while it waits
                self.executor.spin_once(timeout_sec=self._slice)
        except Exception:  # noqa: BLE001 - a crash of a node callback is what we count
            self.crash = traceback.format_exc()

    @property
    def alive(self) -> bool:
        return self.crash is None and self._thread.is_alive()

    # ------------------------------------------------------------------ the sim process
    def _start_sim(self):
        """Start the shipped ``sim_instrument`` on the instrument file, its states relayed."""
        from grip_force_ros.lab.faults.probe import relay_remaps
        from grip_force_ros.lab.processes import NodeProcess, node_command
        log = Path(tempfile.gettempdir()) / f'grip_force_faultcheck_sim_{os.getpid()}.log'
        # normal scheduling, as the controller and the probe in this process: a SCHED_FIFO
        # sim beside them starved them (the probe's master 437 ms stale at load 3). Its state
        # split (joints, actuator on their own topics): the probe faults each input apart.
        return NodeProcess('sim_instrument', command=node_command(
            'sim_instrument', self.config, {'state_message': 'split'},
            remaps=relay_remaps(RELAY_PREFIX)), log_path=log)

    def restart_plant(self, ticks: int, stamp_offset: float = 0.0) -> threading.Event:
        """Restart the instrument: the probe's plant, or kill and start the sim process.

        Returns the event of the fault window (``ticks`` probe ticks of silence; stamps
        shifted by ``stamp_offset`` s from its end on).
        """
        done = self.probe.restart_sim(ticks, stamp_offset)
        if self.sim is None:
            return done
        self.killed = {'pid': self.sim.pid}
        self.sim.popen.kill()               # a crash, not a clean shutdown
        self.killed['exit_code'] = self.sim.popen.wait()
        self.recovery_timeout = PROCESS_READY_TIMEOUT   # a new process has to start

        def start_again():
            done.wait(ticks * self.probe.period * 20 + 2.0)
            if not self._stop:          # a closed session starts no process
                self.sim = self._start_sim()
        self._restarting = threading.Thread(target=start_again, name='faultcheck-sim-restart',
                                            daemon=True)
        self._restarting.start()
        return done

    def replace_sim(self) -> None:
        """Stop the ``sim_instrument`` process (SIGINT, then harder) and start a new one."""
        if self.sim is None:
            return
        self.sim.stop(grace=2.0)
        self.sim = self._start_sim()

    def close(self) -> None:
        from grip_force_ros.lab.harness import unfreeze_heap
        from grip_force_ros.nodes.lifetime import shutdown_once
        self._stop = True
        restarting = getattr(self, '_restarting', None)
        if restarting is not None:      # let a pending restart finish (or see _stop) first
            restarting.join(timeout=5.0)
        if self.sim is not None:
            self.sim.stop(grace=2.0)
        self._thread.join(timeout=2.0)
        try:
            self.executor.shutdown(timeout_sec=1.0)
        except Exception:  # noqa: BLE001
            pass
        for node in (self.probe, self.controller):
            try:
                node.destroy_node()
            except Exception:  # noqa: BLE001
                pass
        shutdown_once(self.context)    # a Ctrl-C may shut the context down under try_shutdown
        unfreeze_heap()

    # ------------------------------------------------------------------ state
    def gripping(self, since: float, samples: int = 20) -> bool:
        """Tell whether the last ``samples`` targets received after ``since`` are all > 0 (grip)."""
        targets = self.probe.targets[-samples:]
        return len(targets) == samples and targets[0][0] >= since and all(t[2] > 0 for t in targets)

    def wait_gripping(self, timeout: float | None = None) -> bool:
        from grip_force_ros.lab.harness import wait_until
        start = self.probe.now()
        return wait_until(lambda: self.gripping(start), timeout or self.ready_timeout)

    # ------------------------------------------------------------------ parameters
    def set_parameters(self, values: dict, atomic: bool = False, timeout: float = 5.0):
        """Set parameters of the controller through its services; list of (ok, reason)."""
        from rclpy.parameter import Parameter
        from rclpy.parameter_client import AsyncParameterClient
        client = getattr(self, '_param_client', None)
        if client is None:
            client = self._param_client = AsyncParameterClient(self.probe, self.controller.get_name())
            if not client.wait_for_services(timeout_sec=timeout):
                raise RuntimeError('controller parameter services not available')
        params = [Parameter(k, value=v) for k, v in values.items()]
        future = (client.set_parameters_atomically if atomic else client.set_parameters)(params)
        done = threading.Event()
        future.add_done_callback(lambda _f: done.set())
        if not done.wait(timeout):
            raise RuntimeError('no answer from the controller parameter service')
        response = future.result()
        results = response.results if hasattr(response, 'results') else [response.result]
        return [(r.successful, r.reason) for r in results]

    def held_inputs(self) -> dict:
        """Return the input values the controller node holds now (its ControlInputs)."""
        inputs = getattr(self.controller, 'inputs', None)
        names = ('master_angle', 'wrist_angle', 'jaw_angle', 'jaw_velocity', 'measured_current',
                 'motor_angle', 'motor_velocity', 'measured_force')
        return {n: float(getattr(inputs, n)) for n in names if hasattr(inputs, n)}

    def violation_count(self) -> int:
        """Limit violations the probe saw in this session, during cases and between them."""
        return len(self.probe.limits.violations) + len(self.probe.force_violations)

    def receive_times(self) -> dict:
        """Source -> the controller's receive time (s) of its last accepted sample."""
        inputs = getattr(self.controller, 'inputs', None)
        return {s: float(getattr(inputs, f'{s}_time', math.nan))
                for s in SOURCES}

    def rejected_count(self) -> int:
        """Count the samples the controller node has rejected so far (its ControlInputs counters)."""
        inputs = getattr(self.controller, 'inputs', None)
        return sum(getattr(inputs, 'rejected', {}).values()) if inputs is not None else 0

    def last_rejection(self) -> str:
        inputs = getattr(self.controller, 'inputs', None)
        rejected = getattr(inputs, 'rejected', {}) if inputs is not None else {}
        return next(reversed(rejected), '') if rejected else ''

    def get_parameter(self, name: str):
        return self.controller.get_parameter(name).value


# ---------------------------------------------------------------------------- analysis
def _modes(probe, t0: float) -> list[tuple]:
    """(receive time, controller stamp, command, target) of the control steps received after t0."""
    return [row for row in probe.steps if row[0] >= t0]


def _first_safe_step(rows: list[tuple], until: float) -> float | None:
    """Return the controller stamp (s) of its first safe step up to ``until``, or None.

    By the controller's own stamp, not by when the probe received the step: on a loaded
    machine the safe steps of a short fault window can reach the probe after the window
    (e.g. 12 steps in a 60 ms window, the safe ones received later).
    """
    return next((r[1] for r in rows if r[3] == 0.0 and r[1] <= until), None)


def _resume_jumps(rows: list[tuple]) -> list[float]:
    """|first command after the safe state - last safe command| at each resume (A)."""
    jumps = []
    for prev, cur in zip(rows, rows[1:]):
        if prev[3] == 0.0 and cur[3] > 0.0:
            jumps.append(abs(cur[2] - prev[2]))
    return jumps


def run_message_case(session: Session, case: FaultCase) -> dict:
    """Inject one message, silence or restart fault and judge its outcome."""
    from grip_force_ros.lab.harness import wait_until
    probe, params = session.probe, session.params
    detail: dict = {'name': case.name, 'category': case.category, 'outcome': case.outcome,
                    'description': case.description, 'plant': session.plant}
    probe.master_angle = GRIP_MASTER_ANGLE if case.master_angle is None else case.master_angle
    session.recovery_timeout = RECOVERY_TIMEOUT
    if not session.wait_gripping():
        detail.update(passed=False, why='controller not gripping before the fault')
        return detail
    violations_before = len(probe.limits.violations) + len(probe.force_violations)
    rejected_before = session.rejected_count()
    probe.clear_records()
    t0 = probe.now()
    if case.kind == 'restart':
        offset = 0.0
        if case.mutate is not None:   # the clock-reset variant carries its stamp shift
            offset = case.mutate({'stamp': 0.0}, 0)[0]['stamp']
        done = session.restart_plant(case.ticks, offset)
    else:
        sources = SOURCES if case.source == 'all' else (case.source,)
        done = probe.inject(sources, case.mutate, case.ticks)
    last_good = dict(probe.last_good_publish)
    # the controller's receive time of the last good sample, read inside the window
    wait_until(lambda: probe.fault_k >= min(10, case.ticks - 1) or done.is_set(), 1.0)
    last_received = session.receive_times()
    held = session.held_inputs()     # what the controller holds while the fault lasts
    done.wait(case.ticks * probe.period * 20 + 2.0)
    attempts = 1
    if case.kind == 'message' and case.ticks <= SINGLE_SAMPLE_TICKS:
        # The controller keeps only the newest sample of a topic (KEEP_LAST 1): a single bad
        # sample that the next good one overtakes before the controller takes it was never
        # delivered. Send it again (the same fault) until the controller has seen one.
        while attempts < SINGLE_SAMPLE_ATTEMPTS and not wait_until(
                lambda: session.rejected_count() > rejected_before, 0.2):
            attempts += 1
            done = probe.inject(sources, case.mutate, case.ticks)
            done.wait(case.ticks * probe.period * 20 + 2.0)
        detail['attempts'] = attempts
    t1 = probe.now()
    relayed_before = probe.relayed   # the killed process's last states are in by now
    recovered = wait_until(lambda: session.gripping(t1), session.recovery_timeout)
    t2 = probe.now()                 # gripping again (or the recovery timed out)
    if case.kind == 'restart' and session.sim is not None:   # the real process, killed and new
        detail['sim_process'] = {'killed_pid': session.killed['pid'],
                                 'exit_code': session.killed['exit_code'], 'new_pid': session.sim.pid,
                                 'alive': session.sim.alive(),
                                 'states_relayed': probe.relayed - relayed_before}
        if not recovered:
            unheard = _unheard_sim(session, detail['sim_process']['states_relayed'])
            if unheard is not None:   # the middleware's doing, not the controller's: redone
                detail['spoiled'] = unheard
                session.replace_sim()     # with a new process
    pattern = re.compile(case.reason, re.I) if case.reason else None
    if pattern is not None:   # /diagnostics may come at a lower rate: give it time
        wait_until(lambda: any(pattern.search(d[1]) for d in probe.diagnostics), 0.5)
    judged = probe.now()             # the diagnostics of the fault's episode are in by now
    rows = _modes(probe, t0)
    window = [r for r in rows if r[0] <= t1 + 0.005]
    safe_rows = [r for r in window if r[3] == 0.0]
    jumps = _resume_jumps(rows)
    step = params.max_current_slew / params.control_rate
    reason_text = next((d[1] for d in probe.diagnostics if pattern and pattern.search(d[1])), None)
    rejected = session.rejected_count() - rejected_before
    detail.update(
        recovered=recovered, safe_periods=len(safe_rows), periods=len(window),
        reason_seen=reason_text,
        max_resume_jump=max(jumps) if jumps else 0.0, slew_step=step,
        limit_violations=len(probe.limits.violations) + len(probe.force_violations) - violations_before,
    )
    problems = []
    if not recovered:
        problems.append('control did not resume within %.1f s' % session.recovery_timeout)
    if jumps and max(jumps) > RESUME_JUMP_SHARE * step + 1e-9:
        problems.append(f'current jump {max(jumps):.4f} A at resume (> {RESUME_JUMP_SHARE} slew step)')
    if case.outcome in ('reject_safe', 'reject_once', 'stale_safe', 'clamp') and reason_text is None:
        problems.append(f'no /diagnostics text matching {case.reason!r}')
    if case.outcome in ('reject_safe', 'stale_safe'):
        first_safe = _first_safe_step(rows, t2)
        detail['first_safe_step_ms'] = None if first_safe is None else round((first_safe - t0) * 1e3, 1)
        if first_safe is None:
            problems.append('output never went to the safe state')
        elif case.outcome == 'reject_safe' and pattern is not None and not any(
                _diag_mode(d[2]) is Mode.SAFE and pattern.search(d[1]) for d in probe.diagnostics):
            problems.append(f'no safe state for the reason {case.reason!r}')
    if case.outcome == 'stale_safe':
        timeout = _case_timeout(case, params)
        detail['watchdog_timeout_ms'] = round(timeout * 1e3, 3)
        latency = _watchdog_latency(case, probe, last_good, rows, session)
        detail['safe_after_last_input_ms'] = None if latency is None else round(latency * 1e3, 3)
        limit = timeout + 2.0 / params.control_rate + WATCHDOG_SLACK
        detail['safe_latency_limit_ms'] = round(limit * 1e3, 3)
        received = _watchdog_latency(case, probe, last_received, rows, session)
        detail['safe_after_last_receive_ms'] = None if received is None else round(received * 1e3, 3)
        steps = _steps_to_safe(case, probe, last_received, rows, timeout)
        detail['controller_steps_after_timeout'] = steps
        if latency is None or steps is None:
            problems.append('no safe output after the last input')
        elif steps > 2:
            problems.append(f'safe only at the {steps}th control period after the timeout')
        elif steps == 0:   # safe before this input's timeout: another input lost first, a stall?
            safe_reason = next((d[1] for d in probe.diagnostics if d[0] <= t1 + 0.005
                                and _diag_mode(d[2]) is Mode.SAFE), None)
            detail['safe_before_timeout'] = (safe_reason or 'no safe-state diagnostic')[:300]
        cause = _watchdog_trial_spoiled(steps, reason_text is not None, probe.diagnostics,
                                        _case_sources(case), judged)
        if cause is not None:   # this trial measured nothing
            detail['spoiled'] = cause[:300]
        elif steps == 0:
            why = detail.get('safe_before_timeout', 'no safe-state diagnostic')
            problems.append(f"safe before its own input's timeout: {why}")
    if case.outcome in ('clamp', 'ignore'):
        modes = [_diag_mode(d[2]) for d in probe.diagnostics if d[0] <= t1 + 0.005]
        modes = [m for m in modes if m is not None]
        if modes:   # the controller reports its mode: free motion is not the safe state
            grip_share = 1.0 - modes.count(Mode.SAFE) / len(modes)
        else:
            grip_share = (len(window) - len(safe_rows)) / max(len(window), 1)
        detail['grip_share'] = round(grip_share, 3)
        # A watchdog trip from a scheduling stall of a loaded machine (an input gone stale,
        # or the controller's own step interval beyond the watchdog: 'the controller was
        # stalled') is not this fault's doing; a safe state for any other reason is.
        unsafe = [d[1] for d in probe.diagnostics
                  if d[0] <= t1 + 0.005 and _diag_mode(d[2]) is Mode.SAFE
                  and not _scheduling_stall(d[1])]
        if unsafe:
            problems.append(f'went to the safe state: {unsafe[0][:200]}')
        if grip_share < 0.5 and unsafe:
            problems.append(f'left grip in {1 - grip_share:.0%} of the fault window')
        elif grip_share < 0.5:   # only for stale inputs or stalls: the machine starved the loop
            detail['spoiled'] = (f'left grip in {1 - grip_share:.0%} of the fault window for '
                                 'stale inputs or a stalled controller only (a starved process)')
    if case.outcome == 'bounded':   # a wrong but plausible input: only the limits stand
        commands = [abs(r[2]) for r in window]
        detail['peak_command'] = max(commands) if commands else math.nan
        detail['max_current'] = params.max_current
    detail['rejected_samples'] = rejected
    if case.outcome == 'ignore' and rejected:
        problems.append(f'{rejected} samples rejected: {session.last_rejection()}')
    bad_held = _implausible(held, params)
    if bad_held:
        problems.append(f'the controller holds an unusable input during the fault: {bad_held}')
    if case.outcome in ('reject_safe', 'reject_once') and not rejected:
        problems.append('no sample was rejected')
    if detail['limit_violations']:
        problems.append('limit violation: ' + (probe.limits.violations + probe.force_violations)[-1])
    detail['passed'] = not problems
    if problems:
        detail['why'] = '; '.join(problems)
    return detail


def _machine_cause(diagnostics: list, silenced: tuple, until: float) -> str | None:
    """Return the first /diagnostics text up to ``until`` (s) that blames the machine, or None.

    Another input than the ``silenced`` ones gone stale, or the controller's own step
    interval beyond its watchdog (a stall of its process: a gen-2 garbage collection of a
    large test process, a starved core). A watchdog case whose output went safe before its
    own input's timeout for such a cause measured nothing.
    """
    return next((d[1] for d in diagnostics if d[0] <= until and (
        CONTROLLER_STALLED in d[1]
        or any(f'stale {s} input' in d[1] for s in SOURCES if s not in silenced))), None)


def _watchdog_trial_spoiled(steps: int | None, own_reason_seen: bool, diagnostics: list,
                            silenced: tuple, until: float) -> str | None:
    """Return the machine cause that spoiled a watchdog trial, or None if it measured the watchdog.

    A trial measured nothing when the output went safe before the silenced input's own
    timeout (``steps == 0``), or when the silenced input's staleness never showed in
    /diagnostics, and a stall of the controller's process or another lost input did (received
    by ``until``, probe clock s). For example, a stall of the process that runs the probe
    and the controller, 150 ms from 10 ms into the 120 ms window of
    ``silence_actuator@sim_instrument``: the first step after the stall finds a fresh
    actuator state and goes safe for 'the controller was stalled' alone, never 'stale
    actuator'.
    """
    if steps != 0 and own_reason_seen:
        return None
    return _machine_cause(diagnostics, silenced, until)


def _unheard_sim(session: Session, states_relayed: int) -> str | None:
    """Say why a restarted ``sim_instrument`` process that runs was never heard, or None.

    A new process that runs (it has not crashed) but none of whose states reached this
    process (the probe relayed none) tells nothing about the controller, which rightly stays
    safe without instrument states: the trial is spoiled. Fast DDS 2.14's shared-memory
    transport can lose a restarted participant that reuses a killed one's port
    (eProsima/Fast-DDS#5053, #4728). The process is asked for its Python stacks (in
    its log, kept beside it), and the cause names how many publishers this process knows on
    its topics and where its main thread was. A process that has died, or has been heard, is
    the case's own failure (None).
    """
    from grip_force_ros.lab.faults.probe import relay_remaps
    sim = session.sim
    if states_relayed or not sim.alive():
        return None
    topics_seen = {topic: session.probe.count_publishers(topic)
                   for topic in relay_remaps(RELAY_PREFIX).values()}
    sim.dump_stacks()
    log = sim.log_tail(200)
    kept = sim.log_path.with_suffix(f'.unheard_{sim.pid}.log')
    kept.write_text(log)
    return (f'the new sim_instrument process (pid {sim.pid}) ran, but none of its states came in '
            f'{session.recovery_timeout:g} s; this process knew {sum(topics_seen.values())} '
            f'publishers on its {len(topics_seen)} topics (a killed one stays known until its '
            f'lease ends, 20 s); its main thread in: {main_thread_frame(log)} (its log: {kept})')


def split_stacks(text: str) -> tuple[str, str]:
    """Split a process's output into what it wrote and the ``faulthandler`` stacks after it."""
    match = STACK_THREAD_HEADER.search(text)
    return (text, '') if match is None else (text[:match.start()], text[match.start():])


def main_thread_frame(stacks: str) -> str:
    """Return the innermost frame of the main thread in ``faulthandler`` output ('' if none).

    The main thread is the one whose outermost frame is a module's top level (below
    ``runpy``'s frames when the process runs ``python -m``, as the process harness starts
    nodes through ``lab/node_process.py``).
    """
    blocks, block = [], []
    for line in stacks.splitlines():
        if STACK_THREAD_HEADER.match(line):
            block = []
            blocks.append(block)
        elif line.startswith('  File ') and blocks and '"<frozen runpy>"' not in line:
            block.append(line.strip())
    for frames in reversed(blocks):
        if frames and frames[-1].endswith('in <module>'):
            return frames[0]
    return ''


def _scheduling_stall(reason: str) -> bool:
    """Whether a safe-state reason is a stall of the machine.

    An input gone stale, or the controller's own step interval beyond its watchdog
    (control/controller.py: ``CONTROLLER_STALLED``).
    """
    return 'stale' in reason or CONTROLLER_STALLED in reason


def run_case_redoing_spoiled(session: Session, case: FaultCase) -> dict:
    """Run a message case; a trial spoiled by the machine is redone, at most twice.

    Spoiled: a watchdog case whose output went safe before its own input's timeout because
    another input was lost first, or a case that must not leave grip whose output did for
    stale inputs or a stall of the controller's own process only (a starved process on a
    loaded machine: found with 10 kHz bursts relayed from the sim process at load 11, and a
    33 ms stall of the in-process controller at load 5). The third spoiled trial fails with its cause.
    """
    return redo_spoiled(lambda: run_message_case(session, case), 'another lost input or a stall')


def _implausible(held: dict, params) -> list:
    """Held input values that are non-finite or outside their plausibility ranges."""
    bad = [f'{k}={v!r}' for k, v in held.items() if not math.isfinite(v)]
    jaw, wrist = held.get('jaw_angle', 0.0), held.get('wrist_angle', 0.0)
    if not params.jaw_angle_min <= jaw <= params.jaw_angle_max:
        bad.append(f'jaw_angle={jaw!r}')
    if abs(wrist) > params.wrist_angle_limit:
        bad.append(f'wrist_angle={wrist!r}')
    master = held.get('master_angle', params.master_angle_min)
    if not params.master_angle_min <= master <= params.master_angle_max:
        bad.append(f'master_angle={master!r}')
    return bad


def _diag_mode(values: dict) -> Mode | None:
    """Find the controller :class:`~grip_force_ros.control.Mode` in a /diagnostics list, or None."""
    for key in ('mode', 'state'):
        try:
            return Mode(values.get(key))
        except ValueError:
            continue
    return None


def _case_sources(case) -> tuple:
    """Input sources a message or restart case silences or faults."""
    if case.kind == 'restart':
        return ('instrument', 'actuator')
    return SOURCES if case.source == 'all' else (case.source,)


def _case_timeout(case, params) -> float:
    """Watchdog timeout (s) that applies to the case: the shortest of its sources'."""
    timeouts = source_timeouts(params)
    return min(timeouts[s] for s in _case_sources(case))


def _watchdog_latency(case, probe, last_good, rows, session):
    """Time from the last good input of the silenced source to the first safe output (s)."""
    sources = _case_sources(case)
    # the last good sample went out just before the fault window began
    # several silenced sources (a restart): the first of them to go stale trips the watchdog
    last = min((last_good[s] for s in sources if last_good.get(s) == last_good.get(s)),
               default=math.nan)
    if last != last:
        return None
    safe = [r for r in rows if r[3] == 0.0 and r[1] >= last]
    if not safe:
        return None
    return safe[0][1] - last


def _steps_to_safe(case, probe, last_good, rows, timeout):
    """Control periods after the watchdog timeout expired until the first safe output.

    ``last_good`` holds the controller's receive time of the last sample of each source.
    Counts the controller's own outputs stamped after ``last receive + timeout`` up to and
    including the first safe one (1 = the first period after the timeout). Independent of
    DDS delivery and of scheduling stalls of a loaded machine, which the wall-clock
    latencies include.
    """
    sources = _case_sources(case)
    # several silenced sources (a restart): the first of them to go stale trips the watchdog
    last = min((last_good[s] for s in sources if last_good.get(s) == last_good.get(s)),
               default=math.nan)
    if last != last:
        return None
    steps = 0
    for r in rows:
        if r[1] - last > timeout:       # the controller's own test (age > timeout), bit for bit
            steps += 1
            if r[3] == 0.0:
                return steps
        elif r[3] == 0.0 and r[1] >= last:
            return 0   # safe before the timeout (e.g. another check tripped first)
    return None


def run_param_set_case(session: Session, case: FaultCase) -> dict:
    """Run a runtime parameter set: refused with a reason (old value kept), or bounded."""
    from grip_force_ros.lab.harness import wait_until
    probe, params = session.probe, session.params
    detail: dict = {'name': case.name, 'category': case.category, 'outcome': case.outcome,
                    'description': case.description}
    before = {k: session.get_parameter(k) for k in case.params}
    violations_before = len(probe.limits.violations) + len(probe.force_violations)
    problems = []
    try:
        results = session.set_parameters(case.params, atomic=len(case.params) > 1)
    except Exception as exc:  # noqa: BLE001
        detail.update(passed=False, why=f'parameter service failed: {exc}')
        return detail
    after = {k: session.get_parameter(k) for k in case.params}
    reasons = [r for ok, r in results if not ok]
    detail['results'] = [{'successful': ok, 'reason': r} for ok, r in results]
    if case.outcome == 'refuse_set':
        if not reasons:
            problems.append('the set was accepted')
        elif case.reason and not any(re.search(case.reason, r, re.I) for r in reasons):
            problems.append(f'reason {reasons[0]!r} does not match {case.reason!r}')
        if after != before:
            problems.append(f'value changed from {before} to {after}')
    else:   # bounded: accepted, the output stays within the hardware limits
        if reasons:
            problems.append(f'refused: {reasons[0]}')
        probe.master_angle = case.master_angle if case.master_angle is not None else GRIP_MASTER_ANGLE
        probe.clear_records()
        t0 = probe.now()
        # the first grip target after the change (a fixed 0.6 s window could pass with none on
        # a starved process), then the peak of the next 0.3 s
        wait_until(lambda: any(f > 0 for recv, _, f in probe.targets if recv >= t0), RECOVERY_TIMEOUT)
        time.sleep(0.3)
        targets = [f for recv, _, f in probe.targets if recv >= t0]
        peak = max(targets) if targets else math.nan
        detail['peak_target_force'] = peak
        detail['max_grip_force'] = params.max_grip_force
        if not targets or not peak > 0:
            problems.append('no grip target after the change')
        elif peak > params.max_grip_force * (1 + 1e-9):
            problems.append(f'target {peak:.3f} N above max_grip_force {params.max_grip_force} N')
        # restore
        session.set_parameters({k: v for k, v in before.items()})
        probe.master_angle = GRIP_MASTER_ANGLE
        wait_until(lambda: session.gripping(probe.now()), RECOVERY_TIMEOUT)
    detail['limit_violations'] = (len(probe.limits.violations) + len(probe.force_violations)
                                  - violations_before)
    if detail['limit_violations']:
        problems.append('limit violation')
    detail['passed'] = not problems
    if problems:
        detail['why'] = '; '.join(problems)
    return detail


def isolated_controller_command(params_file: Path) -> list[str]:
    """Command line of the controller executable on ``params_file``, in :data:`ISOLATION_NS`.

    In a namespace of its own, /diagnostics too: a node that wrongly starts must not drive
    the plant of the in-process cases that run meanwhile.
    """
    return [sys.executable, '-m', 'grip_force_ros.nodes.controller', '--ros-args',
            '--params-file', str(params_file), '-r', f'__ns:={ISOLATION_NS}',
            '-r', f'{topics.DIAGNOSTICS}:={ISOLATION_NS}/diagnostics']


def run_param_file_cases(cases: list[FaultCase], config: Path, timeout: float = 30.0) -> list[dict]:
    """Start the controller executable with each bad parameter file (in parallel)."""
    base = read_params_yaml(config)
    tmp = Path(tempfile.mkdtemp(prefix='grip_force_faultcheck_'))
    procs = []
    for case in cases:
        path = tmp / f'{case.name}.yaml'
        path.write_text(bad_params_text(base, case.params))
        procs.append((case, subprocess.Popen(isolated_controller_command(path), stdout=subprocess.PIPE,
                                             stderr=subprocess.PIPE, text=True, env=dict(os.environ))))
    details = []
    deadline = time.monotonic() + timeout
    for case, proc in procs:
        detail = {'name': case.name, 'category': case.category, 'outcome': case.outcome,
                  'description': case.description}
        stuck_in = None
        try:
            out, err = proc.communicate(timeout=max(0.1, deadline - time.monotonic()))
            code = proc.returncode
        except subprocess.TimeoutExpired:
            # where it was, from its Python stacks (a process with no line on stderr after
            # 30 s: still starting, or stuck?)
            request_stacks(proc.pid)
            proc.kill()
            out, err = proc.communicate()
            err, stacks = split_stacks(err or '')
            stuck_in = main_thread_frame(stacks) or 'no Python stacks'
            code = None
        lines = [ln for ln in (err or '').splitlines() if ln.strip()]
        detail['exit_code'] = code
        detail['stderr'] = lines[-1][:300] if lines else ''
        problems = []
        if code is None:
            detail['main_thread_at_timeout'] = stuck_in
            problems.append(f'the node started with this file (still running after {timeout:g} s; '
                            f'its main thread in: {stuck_in})')
        elif code == 0:
            problems.append('exit code 0')
        if case.reason and not re.search(case.reason, err or '', re.I):
            problems.append(f'stderr does not match {case.reason!r}')
        if 'Traceback' in (err or ''):
            problems.append('a Python traceback instead of a clear message')
        detail['passed'] = not problems
        if problems:
            detail['why'] = '; '.join(problems)
        details.append(detail)
    return details


# ---------------------------------------------------------------------------- all of it
def _run_group(group: list[FaultCase], config: Path, sensor: bool, plant: str, progress=None,
               defect: str | None = None) -> tuple[list[dict], int, int]:
    """Run message, restart and runtime-parameter cases on sessions of one kind.

    A fresh session (controller, probe, plant) after any failure or crash.

    Returns
    -------
    tuple
        (details, crashes, limit violations seen by the sessions).
    """
    details: list[dict] = []
    crashes = violations = 0
    session = None
    for case in group:
        try:
            if session is None:
                session = Session(config, sensor=sensor, plant=plant, defect=defect)
            if case.kind == 'param_set':
                detail = run_param_set_case(session, case)
            else:
                detail = run_case_redoing_spoiled(session, case)
        except Exception:  # noqa: BLE001 - a harness error fails the case, not the run
            detail = {'name': case.name, 'category': case.category, 'outcome': case.outcome,
                      'passed': False, 'why': 'harness error: ' + traceback.format_exc(limit=3)}
        if plant != 'probe':
            detail['name'] = f'{case.name}@{plant}'
        if session is not None and not session.alive:
            crashes += 1
            detail['passed'] = False
            detail['crash'] = (session.crash or 'executor thread ended')[-800:]
            detail['why'] = (detail.get('why', '') + '; controller crashed').lstrip('; ')
        details.append(detail)
        if progress:
            progress(detail)
        if session is not None and (not session.alive or not detail.get('passed')):
            violations += session.violation_count()   # also those between cases
            session.close()   # a fresh controller for the next case
            session = None
    if session is not None:
        violations += session.violation_count()
        session.close()
    return details, crashes, violations


def run_negative_control(config: str | os.PathLike | None = None, progress=None) -> dict:
    """Run each defect's matching cases on a controller with that defect (:mod:`.defects`).

    A defect is caught when one of its cases fails. Its cases are run again, up to
    :data:`DEFECT_TRIALS` times in all, while none has caught it: the defect is in every
    trial, but the machine can hide one (a slew step is judged on the controller's own step
    time, so a controller stalled for 4 ms may jump 0.5 A at once).
    The cases of the product's own check get no such retry.

    Returns
    -------
    dict
        ``cases`` (defects injected), ``caught`` (defects that made at least one case
        fail), ``defects``: per defect its cases, ``caught_by`` (the failing ones, with why),
        ``trials`` (how many were run) and ``missed_trials`` (per trial that caught nothing,
        each case's outcome).
    """
    from grip_force_ros.lab.faults.defects import DEFECTS, negative_control_session
    config = instrument_path(config)
    by_name = {c.name: c for c in catalogue()}
    results = []
    with negative_control_session():
        for defect in DEFECTS.values():
            cases = [by_name[n] for n in defect.cases]
            missed = []
            for trial in range(1, DEFECT_TRIALS + 1):
                details = []
                for sensor in (False, True):
                    group = [c for c in cases if c.sensor == sensor]
                    if group:
                        details += _run_group(group, config, sensor, 'probe', defect=defect.name)[0]
                caught_by = {d['name']: d.get('why', '') for d in details if not d.get('passed')}
                if caught_by:
                    break
                missed.append({d['name']: _case_summary(d) for d in details})
            result = {'defect': defect.name, 'description': defect.description,
                      'cases': list(defect.cases), 'caught': bool(caught_by), 'caught_by': caught_by,
                      'trials': trial, 'missed_trials': missed}
            results.append(result)
            if progress:
                progress(result)
    return {'cases': len(results), 'caught': sum(r['caught'] for r in results), 'defects': results}


def _case_summary(detail: dict) -> dict:
    """Keep the figures of a case run that say why it passed (the negative control misses)."""
    keys = ('peak_command', 'max_current', 'spoiled_trials', 'controller_steps_after_timeout')
    return {k: detail[k] for k in keys if k in detail}


def run_faultcheck(cases: list[FaultCase] | None = None, config: str | os.PathLike | None = None,
                   progress=None, plants=PLANTS, negative_control: bool = True) -> dict:
    """Run ``cases`` (default: the whole catalogue) and return the report.

    Parameters
    ----------
    cases : list of FaultCase, optional
        The cases to run; default the whole catalogue.
    config : path or str, optional
        Instrument YAML (path or shipped name) of the controller under test; default
        :data:`~grip_force_ros.params.files.DEFAULT_INSTRUMENT`.
    progress : callable, optional
        ``progress(detail)`` after each case (and each defect of the negative control).
    plants : sequence of str
        :data:`PLANTS` to run against: every case on the probe's plant, the cases that
        involve the instrument (:func:`involves_instrument`) on the ``sim_instrument``
        process too (named ``<case>@sim_instrument``).
    negative_control : bool
        Also run :func:`run_negative_control`.

    Returns
    -------
    dict
        ``cases``, ``passed``, ``crashes``, ``limit_violations``, ``failures`` (names and
        why), ``details`` (one dict per case run), ``negative_control`` (``{cases, caught,
        defects}``; ``{cases: 0, caught: 0}`` when not run) and ``seconds``.
    """
    from grip_force_ros.lab.processes import reserve_domains
    start = time.monotonic()
    held = None
    if not os.environ.get('ROS_DOMAIN_ID'):   # a domain of its own, held for the run
        held = reserve_domains(1)
        os.environ['ROS_DOMAIN_ID'] = str(held.domain_id)
    try:
        return _run_faultcheck(cases, config, progress, plants, negative_control, start)
    finally:
        if held is not None:
            del os.environ['ROS_DOMAIN_ID']
            held.release()


def _run_faultcheck(cases, config, progress, plants, negative_control, start) -> dict:
    config = instrument_path(config)
    cases = catalogue() if cases is None else list(cases)
    file_cases = [c for c in cases if c.kind == 'param_file']
    file_thread_result: list = []
    file_thread = None
    if file_cases:   # separate processes: run them while the in-process cases run
        file_thread = threading.Thread(
            target=lambda: file_thread_result.extend(run_param_file_cases(file_cases, config)),
            daemon=True)
        file_thread.start()
    details: list[dict] = []
    crashes = violations = 0
    for plant in plants:
        for sensor in (False, True):
            group = [c for c in cases if c.kind not in ('param_file', 'process') and c.sensor == sensor
                     and (plant == 'probe' or involves_instrument(c))]
            if group:
                d, c, v = _run_group(group, config, sensor, plant, progress)
                details += d
                crashes += c
                violations += v
    process_cases = [c for c in cases if c.kind == 'process']
    if process_cases:   # the dVRK interface and the drive, each on its own processes
        from grip_force_ros.lab.faults.dvrk import run_process_cases
        process_details = run_process_cases(process_cases, config, progress)
        details += process_details
        crashes += sum(1 for d in process_details if d.get('crash'))
    if file_thread is not None:
        file_thread.join()
        for detail in file_thread_result:
            details.append(detail)
            if progress:
                progress(detail)
    negative = (run_negative_control(config, progress) if negative_control
                else {'cases': 0, 'caught': 0, 'defects': []})
    failures = [{'name': d['name'], 'why': d.get('why', '')} for d in details if not d.get('passed')]
    return {
        'cases': len(details),
        'passed': sum(bool(d.get('passed')) for d in details),
        'crashes': crashes,
        'limit_violations': violations,
        'failures': failures,
        'negative_control': negative,
        'seconds': round(time.monotonic() - start, 1),
        'details': details,
    }
