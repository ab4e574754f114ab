"""GripController: one control period from plain inputs to a current command."""
from __future__ import annotations

import enum
import math
from typing import NamedTuple

from grip_force_ros.control.force_map import ForceMap
from grip_force_ros.control.inputs import LATE_FACTOR, SOURCES, ControlInputs, source_timeouts
from grip_force_ros.control.limits import CurrentLimiter
from grip_force_ros.control.pid import PID
from grip_force_ros.control.schedule import scheduled_gains
from grip_force_ros.model.dvrk_jaw import command_current_limit

#: F_L / (mu' F_J) for the needle held in three points, F_L = (sqrt2 + 1) mu' F_J (paper)
PULL_OUT_PER_MU = math.sqrt(2.0) + 1.0

#: The words that end a safe-state reason when the controller's own step interval exceeded
#: the watchdog (its process was stalled, not an input lost); lab/faults/runner.py reads them.
CONTROLLER_STALLED = 'the controller was stalled'

#: Default time (s) in which the force target climbs from the estimate to the force map's
#: target when grip resumes after the safe state (the map's target is then a step).
RESUME_RAMP_TIME = 0.1
#: Time constant (s) of the low-pass on the measured current that moves the stick band's
#: state: white current noise would otherwise ratchet the state to the noise's envelope.
STICK_FILTER_TIME = 0.002
#: Sensorless grip: errors below this fraction of the largest force target are not acted
#: on while the stick band holds the force (an integrator would only walk the current
#: across the band, where the force does not change).
HOLD_BAND = 0.005

_isfinite = math.isfinite
_exp = math.exp
_NO_REASONS: tuple = ()


class Mode(enum.StrEnum):
    """What the controller does in a period (a ``str``: /diagnostics shows the value).

    FREE: the master is open, the jaw follows it (jaw-angle PID, no grip force).
    GRIP: the master is closed past contact, the grip force follows the force map.
    SAFE: a required input is missing, stale or invalid; the current ramps to 0 A.
    """

    FREE = 'free'
    GRIP = 'grip'
    SAFE = 'safe'


_FREE, _GRIP, _SAFE = Mode.FREE, Mode.GRIP, Mode.SAFE


class ControlOutput(NamedTuple):
    """Result of one control period (SI units).

    The last three fields are the estimate's band: the grip forces (N) between which the
    sensorless estimate of an instrument with jaw friction terms
    (:attr:`GripController.friction_state`) is held while the jaw sticks, from the chain's
    force through the jaw friction in the closing state (``band_low``) to that in the
    opening state (``band_high``), at this period's current and jaw angle. Inside it a
    change of load does not show in the current. ``estimate_held`` is true while the
    estimate lies strictly inside (held in stick), false while the chain pushes it along an
    edge (the jaw slides: the current shows the force). With the load cell, without jaw
    friction terms and in the safe state there is no band: ``band_low == band_high ==
    estimated_force`` (:attr:`band_width` 0 N) and ``estimate_held`` is false.
    """

    current_command: float      # A, motor current command (positive closes the jaw)
    target_force: float         # N, grip force target (0 in free motion and safe state)
    estimated_force: float      # N, grip force feedback (sensor or model estimate)
    pull_out_force: float       # N, needle pull-out force from estimated_force (0 unless needle)
    mode: Mode                  # free | grip | safe (a str)
    limits_hit: tuple           # of 'current_limit', 'slew_limit'
    reasons: tuple              # of str: why safe, what was clamped or unavailable
    target_jaw_angle: float     # rad, jaw target in free motion, else the measured jaw angle
    feedforward_current: float  # A, inverse-model current for the target force
    band_low: float             # N, the estimate band's low edge (closing friction state)
    band_high: float            # N, the estimate band's high edge (opening friction state)
    estimate_held: bool         # the estimate is held inside the band (the jaw sticks)

    @property
    def band_width(self) -> float:
        """Width of the estimate's band, ``band_high - band_low`` (N); 0 when there is none."""
        return self.band_high - self.band_low


class GripController:
    """Grip-force controller of one instrument.

    Parameters
    ----------
    params : ParamSet
        Instrument, limits and controller parameters (``grip_force_ros.params``).
    model : object, optional
        Provides ``grip_force_scalar(current, wrist, jaw, obj)`` and
        ``current_for_force_scalar(force, wrist, jaw, obj)``; default
        ``GripForceModel(params)`` (with losses). A model whose ``supports_stick_band`` is
        true (:attr:`GripForceModel.supports_stick_band`) also gets the direction-aware
        estimate (:class:`~grip_force_ros.model.hysteresis.HystereticGripForce`); any other
        model is used as the loading branch only.
    resume_ramp_time : float
        Time (s) in which the force target climbs from the estimate to the map's target,
        for the full ``grip_force_max``, when grip resumes after the safe state; 0: no
        ramp (the target steps at once, as before the ramp existed).

    Raises
    ------
    ValueError
        ``resume_ramp_time`` negative or not finite.

    Notes
    -----
    One :meth:`step` per instrument state (nominally ``1 / expected_state_rate`` s apart).
    Every time-dependent part (PID integral, derivative filter, anti-windup, bumpless
    offset, slew limit, stick-band filter, resume ramp) steps on the measured time since
    the previous step, ``now - previous now`` (the controller clock, the clock of the
    inputs' receive times). A step interval that cannot be an integration step is a fault:
    the clock going backwards, or an interval longer than ``watchdog_timeout`` (the
    controller was stalled): that step is safe, and the safe ramp advances by the nominal
    period. In the ``dvrk`` interface the current limit is also that of the tool's jaw
    effort limit (:func:`~grip_force_ros.model.dvrk_jaw.command_current_limit`). The PID
    gains are the designed ones scheduled on ``expected_state_rate``
    (:func:`~grip_force_ros.control.schedule.scheduled_gains`; :attr:`gains`).
    """

    def __init__(self, params, model=None, *, resume_ramp_time: float = RESUME_RAMP_TIME):
        if not (math.isfinite(resume_ramp_time) and resume_ramp_time >= 0.0):
            raise ValueError(f'resume_ramp_time must be finite and >= 0 s, got {resume_ramp_time!r}')
        self.resume_ramp_time = resume_ramp_time
        if model is None:
            from grip_force_ros.model import GripForceModel
            model = GripForceModel(params)
        self.model = model
        self.stick_band = None          # HystereticGripForce, the stick band of the pulleys
        if getattr(model, 'supports_stick_band', False):
            from grip_force_ros.model.hysteresis import HystereticGripForce
            self.stick_band = HystereticGripForce(model)
        self.hysteresis = None          # the stick band when sensorless (set by _configure)
        #: the jaw friction's direction state, stepped with the drum angle; None when the
        #: instrument has no jaw friction terms (the loop is then the chain's alone)
        self.friction_state = None
        friction = getattr(model, 'jaw_friction', None)
        if friction is not None and friction.active:
            from grip_force_ros.model.jaw_friction import FrictionState
            self.friction_state = FrictionState(friction.width)
        #: the grasp goal that commands the jaw instead of the master (control/grasp.py), or
        #: None: the master commands (set by start_goal, ended by end_goal or the safe state)
        self.goal = None
        self._handover = False          # the commander changed: the next step is bumpless
        self._configure(params)
        self.command = 0.0              # A, last output
        self.mode = _SAFE               # starts safe until every input has arrived
        self.retuned = False            # parameters changed at runtime: preset on the next step
        self.estimated_force = 0.0      # N, last good estimate
        #: the jaw friction's band of the last sensorless step (N; ControlOutput.band_low,
        #: band_high) and whether the estimate was held inside it (ControlOutput.estimate_held);
        #: kept only where there is a band (band_status)
        self.band_low = self.band_high = 0.0
        self.estimate_held = False
        self.last_now = -math.inf
        self.last_dt = self.period      # s, the step time of the last step
        self.safe_steps = 0             # consecutive safe periods
        self.steps = 0                  # periods run
        self.limit_steps = 0            # periods in which a limit acted
        self.last_reasons: tuple = ()   # reasons of the last period
        self.branch = 'loading'         # feedforward branch of the stick band (see step)
        self.resume_force = math.inf    # N, ramped force target after safe (inf: no ramp)
        self.last_wrist = 0.0           # rad, last accepted wrist angle
        self.filtered_current = 0.0     # A, low-passed measured current (stick-band state)
        #: late inputs (older than LATE_FACTOR sample intervals, not lost), per source:
        #: episodes that ended with a fresh sample, and the largest age seen (s)
        self.late_counts = dict.fromkeys(SOURCES, 0)
        self.late_max_age = dict.fromkeys(SOURCES, 0.0)
        self._late_now = dict.fromkeys(SOURCES, False)   # an episode is under way
        self._late_age = dict.fromkeys(SOURCES, 0.0)     # s, the oldest age in it so far

    def _configure(self, params) -> None:
        """Build the map, PIDs and limiter from ``params`` (state of the loop kept by caller)."""
        self.params = params
        self.period = 1.0 / params.expected_state_rate                # s, nominal step time
        self.timeouts = source_timeouts(params)                       # s, per input source
        self.watchdog_timeout = self.timeouts['instrument']           # s, also the longest step
        self.object_kind = params.object_kind
        self.use_sensor = bool(params.force_sensor_enabled)
        self.use_feedforward = bool(params.feedforward_enabled)
        # Sensorless: the estimate and the feedforward follow the stick band. With the load
        # cell the feedback sees the branch itself; branch switches computed from a YAML
        # that differs from the plant cost more than they give (docs/control.md).
        hysteresis = None if self.use_sensor else self.stick_band
        if hysteresis is not None and self.hysteresis is None:   # (re)start at the loading edge
            hysteresis.reset()
            self.filtered_current = 0.0
        self.hysteresis = hysteresis
        #: (source, fault attribute, receive-time attribute, interval attribute, timeout [s])
        #: of the inputs the loop needs
        self._required = tuple((src, src + '_fault', src + '_time', src + '_interval',
                                self.timeouts[src])
                               for src in SOURCES
                               if src != 'force' or self.use_sensor)
        #: a grasp goal commands: the master is not needed (autonomy runs with no master)
        self._required_goal = tuple(r for r in self._required if r[0] != 'master')
        self.master_timeout = self.timeouts['master']                 # s
        self.max_grip_force = float(params.max_grip_force)            # N, a goal's cap
        self.pull_out_per_force = (PULL_OUT_PER_MU * params.needle_friction_coefficient
                                   if params.object_kind == 'needle' else 0.0)
        self.force_map = ForceMap.from_params(params)
        self.force_max = self.force_map.force_max                     # N
        self.resume_ramp_rate = (self.force_max / self.resume_ramp_time
                                 if self.resume_ramp_time > 0.0 else math.inf)   # N/s
        self.current_limit = command_current_limit(params)            # A
        self.limiter = CurrentLimiter(self.current_limit, params.max_current_slew, self.period)
        bound = 2.0 * self.current_limit + 1e-3                       # A, integrator guard
        # the designed gains scheduled on the expected state rate (control/schedule.py)
        self.gains = gains = scheduled_gains(params)
        self._gain_status = {'gain_schedule': gains.describe(),
                             'gain_scale': f'force {gains.force_scale:.3f}, jaw {gains.jaw_scale:.3f}'}
        self.force_pid = PID(*gains.force, self.period,
                             params.anti_windup_tracking_time, sign=1.0, integral_limit=bound,
                             bumpless_time=params.bumpless_transfer_time)
        self.jaw_pid = PID(*gains.jaw, self.period,
                           params.anti_windup_tracking_time, sign=-1.0, integral_limit=bound,
                           bumpless_time=params.bumpless_transfer_time)

    def update_params(self, params) -> None:
        """Apply changed (already validated) parameters at runtime, bumplessly.

        Gains, force map and limits are rebuilt; the last command is kept and the next
        period starts with a bumpless transfer (as after a mode switch). The node refuses
        read-only parameters before calling this (the schema marks them).
        """
        gripping, contact = self.force_map.gripping, self.force_map.contact_angle
        self._configure(params)
        self.force_map.gripping, self.force_map.contact_angle = gripping, contact
        self.retuned = True             # the next step presets the PID (bumpless)
        if abs(self.command) > self.current_limit:
            self.command = math.copysign(self.current_limit, self.command)

    def status(self, inputs: ControlInputs | None = None) -> dict:
        """Key/value strings for /diagnostics (state, counters, limits, rejected inputs, gain schedule)."""
        out = {'mode': self.mode.value, 'current_command_A': f'{self.command:.4f}',
               'estimated_force_N': f'{self.estimated_force:.3f}', 'periods': str(self.steps),
               'periods_with_limit_hit': str(self.limit_steps),
               'consecutive_safe_periods': str(self.safe_steps),
               'reasons': '; '.join(self.last_reasons) or 'ok',
               'object_kind': self.object_kind, 'commander': self.commander,
               'feedback': 'force sensor' if self.use_sensor else 'model estimate',
               **self._gain_status}
        out.update(self.band_status())
        out['late_inputs'] = str(sum(self.late_counts.values()))
        for source, count in self.late_counts.items():
            if count:
                out[f'late_{source}'] = str(count)
                out[f'late_{source}_max_ms'] = f'{self.late_max_age[source] * 1e3:.1f}'
        if inputs is not None:
            out['rejected_inputs'] = str(sum(inputs.rejected.values()))
            for reason, count in sorted(inputs.rejected.items(), key=lambda kv: -kv[1])[:5]:
                out[f'rejected: {reason}'] = str(count)
        return out

    def band_status(self) -> dict:
        """Key/value strings of the estimate's band for /diagnostics (forces in N).

        ``estimate``: ``held in stick, band <width> N`` while the estimate is held inside the
        jaw friction's band (a change of load does not show in the current), ``on the band's
        edge (the jaw slides), band <width> N`` while the chain pushes it along an edge,
        ``follows the current, no band`` where the band has no width (no contact); ``load
        cell, no band``, ``no jaw friction terms, no band`` or, in the safe state, ``safe
        state: the last estimate kept, no band``. ``estimate_band_N`` (the width),
        ``estimate_band_low_N`` and ``estimate_band_high_N``: the last step's band.
        """
        low, high = self.band_low, self.band_high
        if self.use_sensor or self.friction_state is None or self.mode is _SAFE:
            low = high = self.estimated_force
        width = high - low
        if self.use_sensor:
            state = 'load cell, no band'
        elif self.friction_state is None:
            state = 'no jaw friction terms, no band'
        elif self.mode is _SAFE:
            state = 'safe state: the last estimate kept, no band'
        elif self.estimate_held:
            state = f'held in stick, band {width:.3f} N'
        elif not width > 0.0:                # no contact, or no Coulomb term: no width
            state = 'follows the current, no band'
        else:
            state = f"on the band's edge (the jaw slides), band {width:.3f} N"
        return {'estimate': state, 'estimate_band_N': f'{width:.3f}',
                'estimate_band_low_N': f'{low:.3f}', 'estimate_band_high_N': f'{high:.3f}'}

    # ------------------------------------------------------------------ who commands
    @property
    def commander(self) -> str:
        """Who commands the jaw: 'master', or 'action' (a grasp goal, with its state)."""
        goal = self.goal
        return 'master' if goal is None else f'action ({goal.state})'

    def start_goal(self, goal) -> None:
        """Let the grasp goal ``goal`` (:class:`~grip_force_ros.control.grasp.GraspGoal`) command.

        It takes over from the master (or preempts the previous goal, aborted with the reason)
        at the next step, bumplessly: the current continues from its last value.
        """
        previous = self.goal
        if previous is not None and previous is not goal:
            previous.abort('preempted by a newer goal')
        self.goal = goal
        self._handover = True

    def end_goal(self) -> None:
        """Hand the jaw back to the master, bumplessly (the force target ramps from the present force)."""
        if self.goal is not None:
            self.goal = None
            self.force_map.reset()
            self._handover = True

    def new_inputs(self) -> ControlInputs:
        """Return an empty :class:`ControlInputs` with this instrument's plausibility ranges."""
        return ControlInputs.from_params(self.params)

    # ------------------------------------------------------------------ checks
    def _input_faults(self, now: float, inputs: ControlInputs):
        """Reasons the inputs cannot be used now (empty tuple when all are good)."""
        if not _isfinite(now):
            return (f'controller clock {now!r} not finite',)
        reasons = None
        late_now = self._late_now
        required = self._required if self.goal is None else self._required_goal
        for source, fault_attr, time_attr, interval_attr, timeout in required:
            fault = getattr(inputs, fault_attr)
            received = getattr(inputs, time_attr)
            why = None
            if fault is not None:
                why = f'invalid input: {fault}'
            elif received != received:
                why = f'no {source} input yet'
            else:
                age = now - received
                if age > timeout:
                    why = f'stale {source} input: {age * 1e3:.1f} ms old > {timeout * 1e3:.1f} ms'
                    late_now[source] = False      # lost, not late: the safe state says so
                    self._late_age[source] = 0.0
                elif age < -timeout:
                    why = f'{source} receive time {-age * 1e3:.1f} ms ahead of the controller clock'
                elif age > LATE_FACTOR * getattr(inputs, interval_attr):   # NaN: never late
                    self._late(source, age)
                elif late_now[source]:            # a fresh sample ended a late episode
                    self._late_ended(source)
            if why is not None:
                reasons = [why] if reasons is None else reasons + [why]
        return _NO_REASONS if reasons is None else tuple(reasons)

    def _late(self, source: str, age: float) -> None:
        """Note a late input (age s): control goes on with its last value; counted when it ends."""
        self._late_now[source] = True
        if age > self._late_age[source]:
            self._late_age[source] = age

    def _late_ended(self, source: str) -> None:
        """Count a late episode that a fresh sample ended (not a loss), with its oldest age."""
        self._late_now[source] = False
        self.late_counts[source] += 1
        if self._late_age[source] > self.late_max_age[source]:
            self.late_max_age[source] = self._late_age[source]
        self._late_age[source] = 0.0

    # ------------------------------------------------------------------ step
    def _step_interval(self, now: float):
        """Return ``(dt [s], fault or None, stalled)``: the time since the previous step, checked.

        A clock that is not finite or went backwards, or an interval longer than
        ``watchdog_timeout``, is a fault; ``dt`` is then the nominal period (for the safe
        ramp). The first step has the nominal period. ``stalled``: the interval was longer than
        the watchdog timeout (the controller was stalled).
        """
        last = self.last_now
        if not _isfinite(now):
            return self.period, None, False   # _input_faults names the clock
        if last == -math.inf:
            return self.period, None, False
        dt = now - last
        if dt < 0.0:
            return self.period, f'controller clock went backwards by {-dt * 1e3:.3f} ms', False
        if dt > self.watchdog_timeout:
            return self.period, (f'step interval {dt * 1e3:.1f} ms > {self.watchdog_timeout * 1e3:.1f} '
                                 f'ms ({CONTROLLER_STALLED})'), True
        return dt, None, False

    def _after_stall(self, now: float, inputs: ControlInputs) -> None:
        """Continue from the current the actuator measures now, after a stall of the controller.

        During a stall longer than the watchdog nobody knows what the drive did with the last
        command: a drive with a command timeout has cut it to 0 A (the sim's does), a dVRK
        holds it. The measured current says which; with no fresh, valid one the command is
        kept. The step after a stall is safe, and the safe ramp only goes toward 0 A: the
        measured current is taken only between 0 A and the last command, so that a stall in
        the safe state cannot take the command back up to a measured current above it.
        """
        age = now - inputs.actuator_time
        if inputs.actuator_fault is None and 0.0 <= age <= self.watchdog_timeout:
            measured, last = inputs.measured_current, self.command   # A
            if last >= 0.0:
                self.command = min(max(measured, 0.0), last)
            else:
                self.command = max(min(measured, 0.0), last)
            self.filtered_current = self.command

    def step(self, now: float, inputs: ControlInputs, interlock: str | None = None) -> ControlOutput:
        """One control step, on the time measured since the previous one.

        Parameters
        ----------
        now : float
            Controller clock (s), the clock of the inputs' receive times.
        inputs : ControlInputs
            Latest accepted samples.
        interlock : str, optional
            Why the instrument may not be driven now (e.g. the dVRK arm is not ENABLED and
            homed): the step is safe with this reason. None: no interlock.

        Returns
        -------
        ControlOutput
        """
        self.steps += 1
        dt, interval_fault, stalled = self._step_interval(now)
        self.last_dt = dt
        faults = self._input_faults(now, inputs)
        if _isfinite(now):
            self.last_now = now
        if interval_fault is not None:
            faults = faults + (interval_fault,)
        if stalled:
            self._after_stall(now, inputs)
        if interlock is not None:
            faults = faults + (interlock,)
        goal = self.goal
        if (goal is not None and goal.done and inputs.master_fault is None
                and now - inputs.master_time <= self.master_timeout   # NaN (none yet): False
                and goal.master_takes_over(inputs.master_angle)):
            self.end_goal()                  # the operator moved the master: it commands again
            goal = None
        if faults:
            return self._safe(faults, inputs)

        wrist, jaw = inputs.wrist_angle, inputs.jaw_angle
        obj = self.object_kind
        reasons = _NO_REASONS
        if inputs.master_clamped:
            reasons = ('master angle clamped to its range',)

        hysteresis = self.hysteresis
        banded = inside = False              # the estimate has a jaw friction band; held inside it
        try:
            if hysteresis is not None:       # sensorless, direction-aware
                measured = inputs.measured_current
                self.filtered_current += ((1.0 - _exp(-dt / STICK_FILTER_TIME))
                                          * (measured - self.filtered_current))
                estimate = hysteresis.update(self.filtered_current, wrist, jaw, obj)
                if hysteresis.on_loading_edge:   # loading: the paper's model, unfiltered
                    estimate = self.model.grip_force_scalar(measured, wrist, jaw, obj)
            elif not self.use_sensor:
                estimate = self.model.grip_force_scalar(inputs.measured_current, wrist, jaw, obj)
            friction = self.friction_state
            if friction is not None:          # the jaw friction: its state follows the drum
                direction = friction.step(inputs.motor_angle)
                if not self.use_sensor:
                    # the jaw holds its force until the chain pushes it out of the friction's
                    # band [closing edge, opening edge]: a stuck jaw's current does not show it
                    chain, model = estimate, self.model
                    low = model.force_through_jaw_friction_scalar(
                        chain, jaw, obj, 1.0, inputs.jaw_velocity, inputs.measured_current, wrist)
                    high = model.force_through_jaw_friction_scalar(
                        chain, jaw, obj, -1.0, inputs.jaw_velocity, inputs.measured_current, wrist)
                    held, banded = self.estimated_force, True
                    estimate = low if held < low else high if held > high else held
                    inside = low < held < high   # held in stick (on an edge: the chain pushes it)
                    self.band_low, self.band_high, self.estimate_held = low, high, inside
        except (ValueError, ArithmeticError) as exc:
            return self._safe((f'force estimate failed: {exc}',), inputs)
        self.last_wrist = wrist
        if self.use_sensor:
            force = inputs.measured_force
        else:
            force = estimate
            if not _isfinite(force):
                return self._safe(('force estimate not finite',), inputs)
        if not banded:                       # no band: its edges are the estimate
            low = high = force

        if goal is None:
            gripping, target = self.force_map.update(inputs.master_angle, jaw, inputs.jaw_velocity,
                                                     dt)
            cap = self.force_max         # N
        else:                            # a grasp goal commands (control/grasp.py)
            gripping, target = goal.update(jaw, inputs.jaw_velocity, force, dt)
            cap = self.max_grip_force    # N (the goal was refused above it)
        previous_mode = self.mode
        retuned, self.retuned = self.retuned, False
        handover, self._handover = self._handover, False
        feedforward = 0.0
        branch_switch = False
        if gripping:
            mode = _GRIP
            target_force = target if target < cap else cap
            if previous_mode is _SAFE or handover:   # resume: ramp up from the present force
                self.resume_force = force if force > 0.0 else 0.0
            if self.resume_force < target_force:
                self.resume_force += self.resume_ramp_rate * dt
                if self.resume_force < target_force:
                    target_force = self.resume_force
                else:
                    self.resume_force = math.inf
            else:
                self.resume_force = math.inf
            # Branch of the stick band for the feedforward, seen from the feedback force:
            # 'loading' reaches a higher force from below (the paper's inverse),
            # 'unloading' a lower one from above (the cable slips back), and once an
            # unloading has arrived, 'middle' holds it with the drum mid-band, where
            # current noise cannot ratchet the force along an edge.
            if hysteresis is not None:
                band = self.params.stick_branch_band * self.force_max
                branch = self.branch
                if target_force > force + band:
                    branch = 'loading'
                elif target_force < force - band:
                    branch = 'unloading'
                elif branch == 'unloading' and abs(target_force - force) < HOLD_BAND * self.force_max:
                    branch = 'middle'
                branch_switch = branch != self.branch
                self.branch = branch
            if self.use_feedforward and target_force > 0.0:
                try:
                    chain_force = target_force
                    if self.friction_state is not None:   # what the chain must give against it
                        if hysteresis is None:
                            direction = 1.0 if target_force >= force else -1.0
                        else:
                            direction = (1.0 if self.branch == 'loading' else -1.0
                                         if self.branch == 'unloading' else self.friction_state.direction)
                        chain_force = self.model.chain_force_for_jaw_friction_scalar(
                            target_force, jaw, obj, direction, inputs.jaw_velocity)
                    if hysteresis is not None:
                        feedforward = hysteresis.current_for_force(chain_force, wrist, jaw, obj,
                                                                   self.branch)
                    else:
                        feedforward = self.model.current_for_force_scalar(chain_force, wrist, jaw, obj)
                except (ValueError, ArithmeticError) as exc:
                    feedforward = 0.0
                    reasons = reasons + (f'no feedforward: {exc}',)
                if not _isfinite(feedforward):
                    feedforward = 0.0
                    reasons = reasons + ('no feedforward: not finite',)
            pid, setpoint, measurement = self.force_pid, target_force, force
            if (hysteresis is not None and not hysteresis.on_loading_edge
                    and abs(target_force - force) < HOLD_BAND * self.force_max):
                measurement = target_force
            target_jaw = jaw
        else:
            mode = _FREE
            target_force = 0.0
            self.branch = 'loading'
            self.resume_force = math.inf
            pid, setpoint, measurement = self.jaw_pid, target, jaw
            target_jaw = target
        if mode is not previous_mode or branch_switch or retuned or handover:
            # bumpless: continue from the last command
            pid.preset(self.command - feedforward, setpoint, measurement)
        unlimited = feedforward + pid.update(setpoint, measurement, dt)
        command, limits_hit = self.limiter.apply(unlimited, self.command, dt)
        pid.track(unlimited - feedforward, command - feedforward, dt)
        self.command = command
        self.mode = mode
        self.safe_steps = 0
        self.estimated_force = force
        self.last_reasons = reasons
        if limits_hit:
            self.limit_steps += 1
        return ControlOutput(command, target_force, force, self.pull_out_per_force * force,
                             mode, limits_hit, reasons, target_jaw, feedforward, low, high, inside)

    def _safe(self, reasons: tuple, inputs: ControlInputs) -> ControlOutput:
        """Safe state: ramp the current to 0 A at the slew limit, keep the last estimate."""
        dt = self.last_dt
        command, limits_hit = self.limiter.apply(0.0, self.command, dt)
        self.command = command
        if self.hysteresis is not None:   # the measurement may be what failed: the current
            try:                          # loop follows the ramped command
                self.filtered_current += ((1.0 - _exp(-dt / STICK_FILTER_TIME))
                                          * (command - self.filtered_current))
                self.hysteresis.drive_torque(self.filtered_current, self.last_wrist)
            except (ValueError, ArithmeticError):
                self.hysteresis.reset()
        self.mode = _SAFE
        self.retuned = False              # leaving safe presets the PID anyway
        self.safe_steps += 1
        self.last_reasons = reasons
        if limits_hit:
            self.limit_steps += 1
        self.force_map.reset()
        goal = self.goal
        if goal is not None:             # a safe state ends the goal, with the reasons
            goal.abort('; '.join(reasons))
            self.goal = None
        force = self.estimated_force
        self.band_low = self.band_high = force
        self.estimate_held = False
        jaw = inputs.jaw_angle
        return ControlOutput(command, 0.0, force, self.pull_out_per_force * force, _SAFE,
                             limits_hit, reasons, jaw if _isfinite(jaw) else 0.0, 0.0,
                             force, force, False)
