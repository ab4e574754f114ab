"""The controller node's services, and the procedures they run inside its control loop.

``~/set_object`` (rcl_interfaces/srv/SetParameters, one parameter ``object_kind``)
    The object model of the feedforward and the force estimate is the parameter
    ``object_kind``: this service sets that parameter, through the same validation as
    ``ros2 param set /controller object_kind ...`` (unknown objects and a change while
    gripping are refused, with the reason in the result), so the two cannot disagree.
``~/tare`` (std_srvs/srv/Trigger)
    Zeroes the load cell and the current sensor: over ``tare_duration`` s of control steps
    with the jaw open (``tare_jaw_open_angle``), in free motion (no grip force), the mean
    load-cell reading and the mean of measured minus commanded current are the sensors'
    offsets; they become the parameters ``load_cell_offset`` and ``current_sensor_offset``.
    Refused, or stopped, while gripping, in the safe state or with the jaw closed.
``~/calibrate`` (std_srvs/srv/Trigger)
    The short load-cell grasp: the node drives a current staircase
    (:class:`~grip_force_ros.identify.procedures.CurrentStaircase`, about 4 s) on the object
    between the jaws (``object_kind``), records it (a log CSV beside the output), fits the
    cable-pulley friction with ``grip-force calibrate`` in a child process (the loop goes on)
    and so writes the calibrated parameter YAML to ``calibration_file``; the response gives
    the fitted values. Refused without a load cell (nobody publishes ``grip/measured_force``),
    while a grasp is held (the master closed past contact), in the safe state or while
    inactive; stopped (the current ramps to 0 A at the slew limit, then the controller
    resumes) when the master closes, an input goes stale, the arm is disabled, the load cell
    falls silent or reads beyond ``max_grip_force``.

Tare and calibration take many control steps, but a service callback must return before
the loop can run again (one thread, the EventsExecutor, which cannot run coroutine
callbacks): they answer later (:class:`DeferredService`, what rclcpp calls a deferred
response). While one runs, the other two refuse.
"""
from __future__ import annotations

import bisect
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from rcl_interfaces.msg import ParameterType, SetParametersResult
from rcl_interfaces.srv import SetParameters
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy_impl
from rclpy.parameter import Parameter
from std_srvs.srv import Trigger

from grip_force_ros import topics
from grip_force_ros.control import Mode
from grip_force_ros.objects import OBJECTS
from grip_force_ros.identify.procedures import (CurrentStaircase, GraspRecording, SensorZero,
                                                calibration_current)
from grip_force_ros.params import to_yaml

#: Longest wait for the first load-cell sample after subscribing to it (s).
FORCE_WAIT = 2.0
#: Longest time the fit (a child process) may take before it is given up (s).
FIT_TIMEOUT = 120.0
#: The interlock reason with which the controller steps while the calibration drives the current.
CALIBRATING = 'calibrating: ~/calibrate drives the current'


class DeferredService:
    """A service whose callback may answer later: it returns None, :meth:`reply` answers.

    rclpy's executors (the EventsExecutor and the Python ones alike) call the service's
    ``send_response(response, header)`` with what the callback returned; here a None keeps
    the request's header for :meth:`reply` instead.
    """

    def __init__(self, node, srv_type, name: str, callback):
        self.node = node
        self.srv_type = srv_type
        self._callback = callback
        self._pending: list = []
        self.service = node.create_service(srv_type, name, self._call)
        self._send = self.service.send_response
        self.service.send_response = self._send_or_keep

    def _call(self, request, response):
        return self._callback(request, response)

    def _send_or_keep(self, response, header) -> None:
        if response is None:
            self._pending.append(header)
        else:
            self._send(response, header)

    def reply(self, response) -> None:
        """Answer every request that is waiting (a client that gave up is skipped)."""
        pending, self._pending = self._pending, []
        for header in pending:
            try:
                self._send(response, header)
            except _rclpy_impl.RCLError as exc:
                self.node.get_logger().warning(f'{self.service.srv_name}: no reply sent: {exc}')


def _trigger_response(success: bool, message: str) -> Trigger.Response:
    return Trigger.Response(success=success, message=message)


class Procedure:
    """A service's work over many control steps; the node calls :meth:`step` instead of the controller's.

    Parameters
    ----------
    node : ControllerNode
        Gives ``controller``, ``inputs``, ``io``, ``params``, ``get_logger()``,
        ``set_parameters()`` and ``end_procedure(procedure)``.
    service : DeferredService
        Answered by :meth:`finish`.
    """

    name = ''

    def __init__(self, node, service: DeferredService):
        self.node = node
        self.service = service
        self.params = node.params
        self.finished = False

    def step(self, now: float, inputs, interlock):
        """Run one control step at ``now`` (s) on ``inputs``; return its ControlOutput."""
        raise NotImplementedError

    def status(self) -> str:
        """Return what it does now, for /diagnostics."""
        return self.name

    @property
    def drives_current(self) -> bool:
        """Whether the procedure, not the controller, chooses the current now."""
        return False

    def finish(self, success: bool, message: str) -> None:
        """Answer the service, log, and hand the loop back to the controller."""
        if self.finished:
            return
        self.finished = True
        logger = self.node.get_logger()
        # one call site per severity: rclpy refuses a second severity at the same line
        if success:
            logger.info(f'~/{self.name}: {message}')
        else:
            logger.warning(f'~/{self.name}: {message}')
        self.service.reply(_trigger_response(success, message))
        self.node.end_procedure(self)

    def cancel(self, why: str) -> None:
        """Stop at once (the node is leaving the active state): the service answers failure."""
        self.finish(False, f'{self.name} stopped: {why}')


def _fresh_force(node, now: float, inputs) -> float | None:
    """Return the load-cell force (N, offset removed) if a valid sample is fresh, else None."""
    if inputs.force_fault is None and now - inputs.force_time <= node.controller.watchdog_timeout:
        return inputs.measured_force
    return None


class Tare(Procedure):
    """``~/tare``: the sensors' offsets from a short window in free motion with the jaw open."""

    name = 'tare'

    def __init__(self, node, service, now: float, load_cell: bool):
        super().__init__(node, service)
        self.zero = SensorZero(self.params.tare_duration)
        self.load_cell = load_cell           # a load cell publishes: zero it too
        self.force_deadline = now + FORCE_WAIT

    def step(self, now, inputs, interlock):
        """Step the controller as usual and average the sensors over the window."""
        controller = self.node.controller
        commanded = controller.command       # A: the command the measured current answers
        out = controller.step(now, inputs, interlock)
        why = tare_refusal(self.node, out, inputs)
        if why is not None:
            self.finish(False, f'tare stopped after {self.zero.samples} samples: {why}')
            return out
        force = None
        if self.load_cell:
            force = _fresh_force(self.node, now, inputs)
            if force is None:
                if self.zero.samples == 0 and now < self.force_deadline:
                    return out               # the load-cell subscription is new: wait
                self.finish(False, 'tare stopped: no fresh load-cell sample on '
                                   f'{self.node.io.names.measured_force}')
                return out
        if self.zero.add(now, inputs.measured_current, commanded, force):
            self._apply()
        return out

    def _apply(self) -> None:
        params, zero = self.params, self.zero
        values = {'current_sensor_offset': params.current_sensor_offset + zero.current_offset}
        if self.load_cell:
            values['load_cell_offset'] = params.load_cell_offset + zero.force_offset
        result = self.node.set_parameters_atomically(
            [Parameter(k, value=float(v)) for k, v in values.items()])
        if not result.successful:
            self.finish(False, f'tare refused: {result.reason}')
            return
        parts = [f'current_sensor_offset {values["current_sensor_offset"]:+.4f} A '
                 f'(was {params.current_sensor_offset:+.4f})']
        if self.load_cell:
            parts.append(f'load_cell_offset {values["load_cell_offset"]:+.4f} N '
                         f'(was {params.load_cell_offset:+.4f})')
        else:
            parts.append(f'no load cell ({self.node.io.names.measured_force} has no publisher): '
                         f'load_cell_offset kept at {params.load_cell_offset:+.4f} N')
        self.finish(True, f'tared over {zero.samples} steps ({self.params.tare_duration:g} s): '
                          + ', '.join(parts))


def tare_refusal(node, out, inputs) -> str | None:
    """Return why the sensors cannot be zeroed now (None: they can)."""
    if out is None:
        return 'no control step yet'
    if out.mode is Mode.SAFE:
        return f'the controller is in the safe state ({"; ".join(out.reasons)})'
    if out.mode is Mode.GRIP or out.target_force > 0.0:
        return (f'gripping ({out.target_force:.2f} N target): the load cell and the current '
                'carry the grip; open the master first')
    open_angle = node.params.tare_jaw_open_angle
    if not inputs.jaw_angle >= open_angle:
        return (f'the jaw is closed ({inputs.jaw_angle:.3f} rad < tare_jaw_open_angle '
                f'{open_angle:g} rad): it may touch something; open it first')
    return None


class Calibration(Procedure):
    """``~/calibrate``: the load-cell grasp staircase, then ``grip-force calibrate`` on it.

    The fit runs in a child process (``python -m grip_force_ros.identify.command --json``, the
    command of ``grip-force calibrate``): in this process it would hold the interpreter's lock
    (its scipy import alone for up to a second on a loaded machine) and starve the loop,
    measured: a 30 ms gap of commands.

    Raises
    ------
    OSError
        The output directory or the parameter file cannot be written (refused at the call).
    """

    name = 'calibrate'

    def __init__(self, node, service, now: float):
        super().__init__(node, service)
        params = self.params
        self.obj = params.object_kind
        self.top = min(calibration_current(params, self.obj, node.controller.model),
                       node.controller.current_limit)
        self.path = calibration_path(params)
        self.log_path = self.path.with_suffix('.log.csv')
        self.path.parent.mkdir(parents=True, exist_ok=True)
        # the parameters as they run, for the fit (written now: a write error refuses at once)
        self._workdir = Path(tempfile.mkdtemp(prefix='grip_force_calibrate_'))
        self.config_path = self._workdir / f'{params.instrument_name}.yaml'
        self.config_path.write_text(to_yaml(params, ('instrument', 'limits', 'controller')))
        self.phase = 'waiting for the load cell'
        self.force_deadline = now + FORCE_WAIT
        self.start = math.nan               # s, controller clock at the staircase's start
        self.command = 0.0                  # A, what the staircase sends
        self.staircase: CurrentStaircase | None = None
        self.recording: GraspRecording | None = None
        self.level = 0
        self.fit: subprocess.Popen | None = None
        self.fit_deadline = math.inf        # s, controller clock

    @property
    def drives_current(self) -> bool:
        """Whether the staircase (or its ramp to 0 A after a stop) chooses the current now."""
        return self.phase in ('staircase', 'stopping')

    def status(self) -> str:
        """Return the phase (and level) for /diagnostics."""
        if self.phase == 'staircase':
            return f'calibrating: level {self.level}/{len(self.staircase.levels)}'
        return f'calibrating: {self.phase}'

    def step(self, now, inputs, interlock):
        """Drive the staircase (the controller steps safe meanwhile), or step the controller."""
        node = self.node
        controller = node.controller
        if self.phase == 'waiting for the load cell':
            out = controller.step(now, inputs, interlock)
            why = calibration_refusal(node, out, inputs)
            fresh = _fresh_force(node, now, inputs) is not None
            if why is None and not fresh and now > self.force_deadline:
                why = f'no load-cell sample within {FORCE_WAIT:g} s on {node.io.names.measured_force}'
            if why is not None:
                self.cancel(why)
            elif fresh:
                self.phase, self.start = 'staircase', now
                self.command = controller.command
                self.staircase = CurrentStaircase(self.top, self.command)
                self.recording = GraspRecording(self.log_path)
            return out
        if self.phase == 'fitting':
            out = controller.step(now, inputs, interlock)
            if self.fit.poll() is not None:
                self._report()
            elif now > self.fit_deadline:
                self.cancel(f'the fit took longer than {FIT_TIMEOUT:g} s')
            return out
        # the staircase, or its ramp to 0 A after a stop: the controller steps safe (its own
        # command ramps to 0 A, and it resumes from 0 A afterwards); its reasons show faults
        out = controller.step(now, inputs, CALIBRATING)
        t = now - self.start
        if self.phase == 'staircase':
            why = self._stop_reason(now, inputs, out, interlock)
            if why is not None:
                self.phase = 'stopping'
                self.service.reply(_trigger_response(
                    False, f'calibration stopped at level {self.level}/{len(self.staircase.levels)} '
                           f'after {t:.2f} s: {why}; the current ramps to 0 A'))
                node.get_logger().warning(f'~/calibrate stopped: {why}')
                self._clean_up()
            else:
                self._record(t, inputs)
        target = self.staircase.current(t) if self.phase == 'staircase' else 0.0
        command, hits = controller.limiter.apply(target, self.command, controller.last_dt)
        self.command = command
        if command == 0.0 and (self.phase == 'stopping' or t >= self.staircase.duration):
            if self.phase == 'stopping':
                self.finished = True         # answered at the stop
                node.end_procedure(self)
            else:
                self._start_fit(now)
        return out._replace(current_command=command, limits_hit=hits, reasons=(self.status(),))

    def _stop_reason(self, now, inputs, out, interlock) -> str | None:
        faults = [r for r in out.reasons if r != CALIBRATING]
        if interlock is not None:
            faults.append(interlock)
        if faults:
            return '; '.join(faults)
        params = self.params
        if inputs.master_angle < params.master_contact_angle:
            return (f'the master closed to {inputs.master_angle:.3f} rad, past the contact angle '
                    f'{params.master_contact_angle:g} rad: the surgeon takes over')
        force = _fresh_force(self.node, now, inputs)
        if force is None:
            return f'no fresh load-cell sample on {self.node.io.names.measured_force}'
        if force > params.max_grip_force:
            return f'the load cell reads {force:.2f} N > max_grip_force {params.max_grip_force:g} N'
        return None

    def _record(self, t: float, inputs) -> None:
        staircase = self.staircase
        self.level = bisect.bisect_right(staircase.times[1:-1:2], t)
        if t <= staircase.hold_end:
            self.recording.add(t, inputs.measured_current, inputs.motor_angle, inputs.wrist_angle,
                               inputs.jaw_angle, inputs.measured_force)

    def _start_fit(self, now: float) -> None:
        """Start the fit in a child: the staircase is over (0 A), the controller resumes."""
        self.phase = 'fitting'
        self.recording.close()
        self.fit_deadline = now + FIT_TIMEOUT
        self.fit = subprocess.Popen(
            [sys.executable, '-m', 'grip_force_ros.identify.command', '--config', str(self.config_path),
             '--log', str(self.log_path), '--out', str(self.path), '--object', self.obj, '--json'],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)

    def _report(self) -> None:
        out, err = self.fit.communicate()
        self._clean_up()
        if self.fit.returncode != 0:
            lines = [line for line in err.splitlines() if line.strip()]
            self.finish(False, f'calibration failed: {lines[-1] if lines else "no output"} '
                               f'(grip-force calibrate exit {self.fit.returncode}; log {self.log_path})')
            return
        try:
            report = json.loads(out)
        except ValueError as exc:
            self.finish(False, f'calibration failed: grip-force calibrate printed no JSON ({exc})')
            return
        fitted = ', '.join(f'{k} {v:.5f} +/- {report["std_error"][k]:.5f} (was '
                           f'{report["shipped"][k]:.5f})' for k, v in report['fitted'].items())
        self.finish(True, (
            f'{fitted}; residual {report["residual_rms"]:.4f} N (was '
            f'{report["residual_rms_before"]:.4f} N) over {report["n_plateaus"]} plateaus at '
            + ', '.join(f'{f:.2f}' for f in report['force_levels'])
            + f' N ({self.obj}); wrote {self.path} (the controller uses it once started with '
              f'it; the grasp: {self.log_path})'))

    def _clean_up(self) -> None:
        if self.recording is not None:
            self.recording.close()
        if self.fit is not None and self.fit.poll() is None:
            self.fit.kill()
            self.fit.communicate()
        shutil.rmtree(self._workdir, ignore_errors=True)

    def cancel(self, why: str) -> None:
        """Stop at once (refused while waiting, or the node leaves the active state)."""
        self._clean_up()
        super().cancel(why)


def calibration_path(params) -> Path:
    """Return where ~/calibrate writes: ``calibration_file``, else under $ROS_HOME (~/.ros)."""
    if params.calibration_file:
        return Path(params.calibration_file).expanduser()
    home = Path(os.environ.get('ROS_HOME') or Path.home() / '.ros')
    return home / 'grip_force_ros' / f'{params.instrument_name}_calibrated.yaml'


def calibration_refusal(node, out, inputs) -> str | None:
    """Return why the calibration grasp cannot run now (None: it can)."""
    if out is None:
        return 'no control step yet'
    if out.mode is Mode.SAFE:
        return f'the controller is in the safe state ({"; ".join(out.reasons)})'
    params = node.params
    if out.mode is Mode.GRIP or inputs.master_angle < params.master_contact_angle:
        return (f'a grasp is held (master at {inputs.master_angle:.3f} rad, contact angle '
                f'{params.master_contact_angle:g} rad): open the master first, the staircase '
                'would take the jaw from the surgeon')
    return None


class ControllerServices:
    """Create the three services on ``node`` and run their procedures.

    Parameters
    ----------
    node : ControllerNode
        See :class:`Procedure`; also ``active`` (bool), ``last_output``, ``procedure``,
        ``start_procedure(procedure)``.
    """

    def __init__(self, node):
        self.node = node
        self.set_object = node.create_service(SetParameters, topics.SET_OBJECT_SRV,
                                              self._on_set_object)
        self.tare = DeferredService(node, Trigger, topics.TARE_SRV, self._on_tare)
        self.calibrate = DeferredService(node, Trigger, topics.CALIBRATE_SRV, self._on_calibrate)

    # ------------------------------------------------------------------ ~/set_object
    def _on_set_object(self, request, response):
        given = list(request.parameters)
        if (len(given) != 1 or given[0].name != 'object_kind'
                or given[0].value.type != ParameterType.PARAMETER_STRING):
            names = [p.name for p in given]
            response.results = [SetParametersResult(
                successful=False,
                reason=f'set_object takes one string parameter object_kind (free, rigid, tissue '
                       f'or needle), got {names}')]
            return response
        response.results = self.node.set_parameters([Parameter.from_parameter_msg(given[0])])
        return response

    def object_change_refusal(self, parameters) -> str | None:
        """Return why ``parameters`` may not be set now (object_kind while gripping), else None."""
        node = self.node
        change = next((p for p in parameters if p.name == 'object_kind'
                       and p.value != node.params.object_kind), None)
        if change is None or change.value not in OBJECTS:
            return None   # no change, or a value the schema's own check refuses, with its reason
        if isinstance(node.procedure, Calibration):
            return f'object_kind cannot change during ~/calibrate ({node.procedure.status()})'
        out = node.last_output
        if node.active and out is not None and out.mode is Mode.GRIP:
            return (f'object_kind cannot change from {node.params.object_kind!r} to '
                    f'{change.value!r} while gripping ({out.target_force:.2f} N target, '
                    f'{out.estimated_force:.2f} N estimated): the contact model under the held '
                    'force would switch; open the master first')
        return None

    # ------------------------------------------------------------------ ~/tare, ~/calibrate
    def _busy(self, what: str) -> str | None:
        node = self.node
        if not node.active:
            return (f'{what} needs the active controller (lifecycle state {node.lifecycle_state}): '
                    f'ros2 lifecycle set {node.get_fully_qualified_name()} activate')
        if node.procedure is not None:
            return f'{what} refused: ~/{node.procedure.name} is running ({node.procedure.status()})'
        return None

    def _on_tare(self, request, response):
        node = self.node
        why = self._busy('tare')
        if why is None:
            why = tare_refusal(node, node.last_output, node.inputs)
            why = why and f'tare refused: {why}'
        if why is not None:
            response.success, response.message = False, why
            return response
        load_cell = node.load_cell_publishers() > 0
        node.start_procedure(Tare(node, self.tare, node.now(), load_cell), load_cell)
        return None

    def _on_calibrate(self, request, response):
        node = self.node
        why = self._busy('calibration')
        if why is None:
            why = calibration_refusal(node, node.last_output, node.inputs)
            if why is None and node.params.object_kind == 'free':
                why = ("object_kind is 'free': set it to what the jaws close on (the load cell "
                       "as a needle: ~/set_object needle)")
            if why is None and node.load_cell_publishers() == 0:
                why = (f'no load cell: nobody publishes {node.io.names.measured_force}; the fit '
                       'needs the measured grip force')
            why = why and f'calibration refused: {why}'
        if why is not None:
            response.success, response.message = False, why
            return response
        try:
            procedure = Calibration(node, self.calibrate, node.now())
        except OSError as exc:
            response.success = False
            response.message = f'calibration refused: cannot write its files: {exc}'
            return response
        node.start_procedure(procedure, True)
        return None

    def stop(self, why: str) -> None:
        """Stop a running procedure (the node leaves the active state); it answers failure."""
        procedure = self.node.procedure
        if procedure is not None and not procedure.finished:
            procedure.cancel(why)
