"""The fault catalogue: every fault the controller must survive, with its defined outcome.

ROS-free. A message fault is a *mutator*: a function of one good input sample (a plain
dict, see :func:`good_samples`) and the tick index within the fault window, returning the
list of samples to publish instead (``[]`` = silence, several = duplicates or a burst).
The probe (:mod:`grip_force_ros.lab.faults.probe`) turns the dicts into ROS messages.

Outcomes (:data:`OUTCOMES`):

``reject_safe``
    Every faulty sample is rejected with the reason on /diagnostics; the last good value
    is not overwritten, the source counts as faulted, so the output goes to the safe state
    (target force 0 N, current ramping to 0 A at the slew limit) until good samples return;
    then control resumes without a current jump.
``reject_once``
    One faulty sample among good ones: rejected with the reason on /diagnostics, the last
    good input kept; the output is safe at most until the next good sample (possibly not
    at all, when that sample arrives before the next control period).
``clamp``
    The sample is used after clamping to its range, flagged on /diagnostics; control goes on.
``ignore``
    Nothing changes: the controller stays in its mode, no rejection is reported.
``stale_safe``
    The source is silent (or its duplicates do not count as news): the watchdog puts the
    output in the safe state within two control periods of ``watchdog_timeout``, with the
    reason on /diagnostics; control resumes without a current jump.
``refuse_set``
    A runtime parameter set is refused with the reason; the old value stays.
``bounded``
    A runtime parameter set is accepted, or an input is plausible but wrong (a load cell
    stuck at 0 N), and the hardware limits still bound the output.
``refuse_start``
    A node given this parameter file exits non-zero, naming the problem on stderr.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable

#: Input sources, as the controller core names them.
from grip_force_ros.control.inputs import SOURCES  # noqa: F401 - re-exported for the cases' sources

NAN = math.nan
INF = math.inf

#: Trials of a case that a loaded machine spoils: a spoiled trial is redone, at most twice
#: (:func:`redo_spoiled`).
CASE_ATTEMPTS = 3


def redo_spoiled(run_trial: Callable[[], dict], spoiled_by: str) -> dict:
    """Run a case's trial; a trial the machine spoiled is redone, at most twice.

    Parameters
    ----------
    run_trial : callable
        Runs one trial and returns its detail dict; ``detail['spoiled']`` (a cause) marks
        a trial the machine spoiled (what spoils one is the caller's to say).
    spoiled_by : str
        What spoils a trial, for the failure message ('a stalled machine', ...).

    Returns
    -------
    dict
        The last trial's detail, with ``spoiled_trials`` (the causes, in order); after
        :data:`CASE_ATTEMPTS` spoiled trials ``passed`` is False and ``why`` lists them.
    """
    spoiled = []
    for _ in range(CASE_ATTEMPTS):
        detail = run_trial()
        if not detail.get('spoiled'):
            break
        spoiled.append(detail['spoiled'])
    else:
        detail['passed'] = False
        detail['why'] = f'spoiled {CASE_ATTEMPTS} times by {spoiled_by}: ' + ' | '.join(spoiled)
    detail['spoiled_trials'] = spoiled
    return detail


OUTCOMES = {
    'reject_safe': 'rejected with the reason on /diagnostics, last good input kept, output safe '
                   'while faulted, control resumes without a current jump',
    'reject_once': 'a single bad sample: rejected with the reason on /diagnostics, safe at most '
                   'until the next good sample',
    'clamp': 'used after clamping to its range, flagged on /diagnostics, control goes on',
    'ignore': 'no effect: no rejection, the controller keeps its mode',
    'stale_safe': 'watchdog: safe state within two control periods of the timeout, reason on '
                  '/diagnostics, resumes without a current jump',
    'refuse_set': 'runtime parameter set refused with the reason, old value kept',
    'bounded': 'runtime parameter set accepted, or a plausible but wrong input used; hardware '
               'limits still bound the output',
    'refuse_start': 'node exits non-zero with the offending key on stderr',
    # the dVRK interface and the drive, on real node processes (lab/faults/dvrk.py)
    'drive_cut': "the controller process dies mid-grasp: the sim's drive cuts the current to 0 A "
                 'within 35 ms (its 30 ms command timeout), reported',
    'arm_interlock': 'the arm leaves ENABLED: the controller goes safe naming the arm state, sends '
                     'no more jaw effort and does not enable the arm again; no current',
    'effort_refused': "a jaw effort beyond the tool's limit is refused with a warning; the current "
                      'stays',
}


Mutator = Callable[[dict, int], list]

#: (source, field) the controller does not read: a non-finite value there has no effect.
#: The master's velocity is not used (the force map works on the angle alone).
UNUSED_FIELDS = {('master', 'velocity')}


@dataclass(frozen=True)
class FaultCase:
    """One fault of the catalogue.

    Attributes
    ----------
    name : str
        Unique, snake_case.
    category : str
        What kind of fault ('non-finite', 'array length', 'joint names', 'range',
        'master range', 'timestamps', 'duplicates', 'burst', 'silence', 'sim restart',
        'runtime parameters', 'parameter file').
    description : str
        The fault in words.
    outcome : str
        Key of :data:`OUTCOMES`.
    source : str or None
        Input source the fault is injected on (message faults).
    mutate : callable or None
        ``mutate(sample, k) -> list of samples`` for message faults.
    ticks : int
        Length of the fault window in probe ticks (1 ms each).
    reason : str
        Regular expression expected in the /diagnostics text, the refusal reason or stderr.
    sensor : bool
        Needs a controller with ``force_sensor_enabled``.
    params : dict
        Runtime parameter set (``refuse_set``/``bounded``) or parameter file edits
        (``refuse_start``; the key ``__text__`` replaces the whole file).
    master_angle : float or None
        Master gripper angle (rad) the probe holds during the case (None: the default grip).
    """

    name: str
    category: str
    description: str
    outcome: str
    source: str | None = None
    mutate: Mutator | None = None
    ticks: int = 60
    reason: str = ''
    sensor: bool = False
    params: dict = field(default_factory=dict)
    master_angle: float | None = None

    @property
    def kind(self) -> str:
        """'message', 'restart', 'param_set' or 'param_file'."""
        if self.outcome == 'refuse_start':
            return 'param_file'
        if self.outcome == 'refuse_set' or (self.outcome == 'bounded' and self.source is None):
            return 'param_set'
        if self.category == 'sim restart':
            return 'restart'
        if self.category in ('process', 'dvrk interface'):
            return 'process'
        return 'message'


# ---------------------------------------------------------------------------- mutators
def set_field(field_name: str, index: int, value: float) -> Mutator:
    """Replace element ``index`` of a JointState field (or ``'force'``) by ``value``."""
    def mutate(sample: dict, k: int) -> list:
        s = dict(sample)
        if field_name == 'force':
            s['force'] = value
        else:
            values = list(s[field_name])
            values[index] = value
            s[field_name] = values
        return [s]
    return mutate


def resize(field_name: str, length: int) -> Mutator:
    """Give a JointState field ``length`` values (pad with 0.0 or truncate)."""
    def mutate(sample: dict, k: int) -> list:
        s = dict(sample)
        values = list(s[field_name])[:length]
        s[field_name] = values + [0.0] * (length - len(values))
        return [s]
    return mutate


def rename(names: list) -> Mutator:
    """Replace the joint names; the value arrays follow the new length (padded with 0.0)."""
    def mutate(sample: dict, k: int) -> list:
        s = dict(sample)
        n = len(names)
        s['name'] = list(names)
        for f in ('position', 'velocity', 'effort'):
            if s.get(f):
                values = list(s[f])[:n]
                s[f] = values + [0.0] * (n - len(values))
        return [s]
    return mutate


def shift_stamp(offset: float) -> Mutator:
    """Stamp every sample ``offset`` seconds off its true time."""
    def mutate(sample: dict, k: int) -> list:
        return [dict(sample, stamp=sample['stamp'] + offset)]
    return mutate


def fixed_stamp(stamp: float) -> Mutator:
    """Every sample carries the same stamp ``stamp`` (s), e.g. 0 for an unstamped driver."""
    def mutate(sample: dict, k: int) -> list:
        return [dict(sample, stamp=stamp)]
    return mutate


def duplicate_each(copies: int = 2) -> Mutator:
    """Send every sample ``copies`` times with the same stamp."""
    def mutate(sample: dict, k: int) -> list:
        return [dict(sample) for _ in range(copies)]
    return mutate


def frozen_stamp() -> Mutator:
    """Fresh values under the stamp of the window's first sample (a stuck driver).

    A new window (its tick index ``k`` falls back) starts from its own first sample, also
    when that sample does not come at tick 0 (samples relayed from another process).
    """
    first: dict = {}

    def mutate(sample: dict, k: int) -> list:
        if 'stamp' not in first or k < first['k']:
            first['stamp'] = sample['stamp']
        first['k'] = k
        return [dict(sample, stamp=first['stamp'])]
    return mutate


def burst(factor: int = 10, period: float = 1e-3) -> Mutator:
    """``factor`` samples per tick with stamps spread over the period (``factor`` x rate)."""
    def mutate(sample: dict, k: int) -> list:
        return [dict(sample, stamp=sample['stamp'] - period + (i + 1) * period / factor)
                for i in range(factor)]
    return mutate


def silence() -> Mutator:
    """Publish nothing."""
    def mutate(sample: dict, k: int) -> list:
        return []
    return mutate


def then_silence(first: Mutator, ticks: int) -> Mutator:
    """Apply ``first`` for ``ticks`` probe ticks, then publish nothing."""
    def mutate(sample: dict, k: int) -> list:
        return first(sample, k) if k < ticks else []
    return mutate


# ---------------------------------------------------------------------------- the catalogue
def _message_cases() -> list[FaultCase]:
    C = FaultCase
    cases: list[FaultCase] = []
    # --- non-finite values in every field the controller reads
    nonfinite = [
        ('master', 'position', 0, 'gripper angle'), ('master', 'velocity', 0, 'gripper velocity'),
        ('instrument', 'position', 0, 'wrist angle'), ('instrument', 'position', 1, 'jaw angle'),
        ('instrument', 'velocity', 1, 'jaw velocity'), ('instrument', 'velocity', 0, 'wrist velocity'),
        ('actuator', 'effort', 0, 'measured current'), ('actuator', 'position', 0, 'drum angle'),
        ('actuator', 'velocity', 0, 'drum velocity'),
    ]
    for i, (source, fld, idx, what) in enumerate(nonfinite):
        value = NAN if i % 2 == 0 else (INF if i % 4 == 1 else -INF)
        tag = 'nan' if value != value else ('inf' if value > 0 else 'neg_inf')
        unused = (source, fld) in UNUSED_FIELDS
        cases.append(C(f'{tag}_{source}_{what.replace(" ", "_")}', 'non-finite',
                       f'{what} ({source} {fld}[{idx}]) = {value}'
                       + (' (a field the controller does not read)' if unused else ''),
                       'ignore' if unused else 'reject_safe', source,
                       set_field(fld, idx, value),
                       reason='' if unused else r'nan|inf|not finite|non-finite'))
    # the other non-finite value in the fields that decide the command
    cases.append(C('inf_master_gripper_angle', 'non-finite', 'gripper angle = +inf',
                   'reject_safe', 'master', set_field('position', 0, INF),
                   reason=r'inf|not finite|non-finite'))
    cases.append(C('inf_instrument_jaw_angle', 'non-finite', 'jaw angle = +inf',
                   'reject_safe', 'instrument', set_field('position', 1, INF),
                   reason=r'inf|not finite|non-finite'))
    cases.append(C('inf_actuator_measured_current', 'non-finite', 'measured current = +inf',
                   'reject_safe', 'actuator', set_field('effort', 0, INF),
                   reason=r'inf|not finite|non-finite'))
    # a single bad sample among good ones: one or two safe periods, the reason still reported
    cases.append(C('single_nan_jaw_angle', 'non-finite', 'one jaw angle = nan among good samples',
                   'reject_once', 'instrument', set_field('position', 1, NAN), ticks=1,
                   reason=r'nan|not finite|non-finite'))
    # --- wrong array lengths
    cases += [
        C('short_instrument_position', 'array length', '1 position for 2 joints', 'reject_safe',
          'instrument', resize('position', 1), reason=r'position has 1 value'),
        C('long_master_position', 'array length', '3 positions for 1 joint', 'reject_safe',
          'master', resize('position', 3), reason=r'position has 3 value'),
        C('empty_actuator_effort', 'array length', 'no effort (measured current)', 'reject_safe',
          'actuator', resize('effort', 0), reason=r'effort has 0 value'),
    ]
    # --- joint names
    cases += [
        C('missing_joint_jaw', 'joint names', "instrument message without the 'jaw' joint",
          'reject_safe', 'instrument', rename(['wrist_pitch']), reason=r"missing joint.*jaw"),
        C('unknown_joint_instrument', 'joint names', "an extra joint 'elbow'", 'reject_safe',
          'instrument', rename(['wrist_pitch', 'jaw', 'elbow']), reason=r'unknown joint.*elbow'),
        C('unknown_joint_master', 'joint names', "master joint named 'gripper_2'", 'reject_safe',
          'master', rename(['gripper_2']), reason=r'unknown joint.*gripper_2'),
        C('empty_actuator_message', 'joint names', 'actuator message with no joints',
          'reject_safe', 'actuator', rename([]), reason=r'missing joint.*jaw_drum'),
    ]
    # --- out-of-range measured values
    cases += [
        C('jaw_angle_above_range', 'range', 'jaw angle 3.0 rad (beyond jaw_angle_max)',
          'reject_safe', 'instrument', set_field('position', 1, 3.0), reason=r'jaw angle.*outside'),
        C('jaw_angle_below_range', 'range', 'jaw angle -0.5 rad (below jaw_angle_min)',
          'reject_safe', 'instrument', set_field('position', 1, -0.5), reason=r'jaw angle.*outside'),
        C('wrist_angle_out_of_range', 'range', 'wrist pitch 2.0 rad (beyond wrist_angle_limit)',
          'reject_safe', 'instrument', set_field('position', 0, 2.0), reason=r'wrist angle.*beyond'),
        C('measured_current_out_of_range', 'range', 'measured current 5 A (> 2 max_current)',
          'reject_safe', 'actuator', set_field('effort', 0, 5.0), reason=r'measured current.*beyond'),
    ]
    # --- master angle below / above its range
    cases += [
        C('master_slightly_below_range', 'master range',
          'master -0.2 rad: below master_angle_min, within master_angle_tolerance', 'clamp',
          'master', set_field('position', 0, -0.2), reason=r'clamped'),
        C('master_slightly_above_range', 'master range',
          'master 1.5 rad: above master_angle_max, within master_angle_tolerance', 'clamp',
          'master', set_field('position', 0, 1.5), reason=r'clamped'),
        C('master_far_below_range', 'master range', 'master -1.0 rad: beyond the tolerance',
          'reject_safe', 'master', set_field('position', 0, -1.0), reason=r'gripper angle.*outside'),
        C('master_far_above_range', 'master range', 'master 2.5 rad: beyond the tolerance',
          'reject_safe', 'master', set_field('position', 0, 2.5), reason=r'gripper angle.*outside'),
    ]
    # --- timestamps
    cases += [
        # a jump back is rejected once; the stamps that follow it increase and are used
        C('stamp_backwards_instrument', 'timestamps', 'instrument stamps jump 1 s back',
          'reject_once', 'instrument', shift_stamp(-1.0), reason=r'backwards'),
        C('stamp_backwards_master', 'timestamps', 'master stamps jump 0.5 s back',
          'reject_once', 'master', shift_stamp(-0.5), reason=r'backwards'),
        C('stamp_future_actuator', 'timestamps', 'actuator stamps 10 s in the future',
          'reject_safe', 'actuator', shift_stamp(10.0), reason=r'ahead'),
        C('stamp_future_master', 'timestamps', 'master stamps 1 h in the future',
          'reject_safe', 'master', shift_stamp(3600.0), reason=r'ahead'),
        C('unstamped_instrument', 'timestamps',
          'instrument messages with a zero (unset) header stamp, as from a driver that does not '
          'stamp: used by their receive time, the watchdog still applies', 'ignore',
          'instrument', fixed_stamp(0.0), ticks=120),
    ]
    # --- duplicates and bursts
    cases += [
        C('duplicate_instrument', 'duplicates', 'every instrument message sent twice (same stamp)',
          'ignore', 'instrument', duplicate_each(2), ticks=200),
        C('duplicate_master', 'duplicates', 'every master message sent three times',
          'ignore', 'master', duplicate_each(3), ticks=200),
        C('frozen_stamp_actuator', 'duplicates',
          'actuator keeps sending one stamp (a stuck driver): duplicates are no news',
          'stale_safe', 'actuator', frozen_stamp(), ticks=120, reason=r'stale actuator'),
        C('burst_10x_instrument', 'burst', 'instrument messages at 10 kHz (10x rate)', 'ignore',
          'instrument', burst(10), ticks=200),
        C('burst_10x_all', 'burst', 'every input topic at 10 kHz (10x rate)', 'ignore', 'all',
          burst(10), ticks=150),
    ]
    # --- silence on each input topic
    for source, ticks in (('master', 120), ('instrument', 120), ('actuator', 120)):
        cases.append(C(f'silence_{source}', 'silence', f'no {source} messages for {ticks} ms',
                       'stale_safe', source, silence(), ticks=ticks, reason=f'stale {source}'))
    # --- the force sensor (controller with force_sensor_enabled)
    cases += [
        C('silence_force_sensor', 'silence', 'no load-cell messages for 120 ms', 'stale_safe',
          'force', silence(), ticks=120, reason=r'stale force', sensor=True),
        C('nan_force_sensor', 'non-finite', 'load-cell grip force = nan', 'reject_safe', 'force',
          set_field('force', 0, NAN), reason=r'nan|not finite|non-finite', sensor=True),
        C('force_sensor_out_of_range', 'range', 'load-cell grip force 1e4 N', 'reject_safe',
          'force', set_field('force', 0, 1e4), reason=r'grip force.*beyond', sensor=True),
        # plausible and wrong: nothing can reject it; the force loop winds up to the limit
        C('force_sensor_stuck_at_zero', 'range',
          'load cell stuck at 0 N (a dead sensor) while gripping: the force loop drives the current '
          'up, the current and slew limits must hold', 'bounded', 'force', set_field('force', 0, 0.0),
          ticks=150, sensor=True),
        # the same dead sensor, then silent: the safe ramp starts from the wound-up current
        # (max_current), the largest a safe ramp takes down. At the probe's default grip the
        # paper instrument holds ~0.06-0.08 A, less than one slew step, where a missing slew
        # limit cannot be seen at all.
        C('force_sensor_stuck_then_silent', 'silence',
          'load cell stuck at 0 N for 120 ms (the current winds up to max_current), then silent for '
          '120 ms: the current and slew limits hold through the safe ramp from max_current',
          'bounded', 'force', then_silence(set_field('force', 0, 0.0), 120), ticks=240,
          sensor=True),
    ]
    # --- the simulated instrument restarts
    cases += [
        C('sim_restart', 'sim restart',
          'instrument and actuator publishers destroyed, 150 ms gap, plant reset, new publishers',
          'stale_safe', 'restart', None, ticks=150, reason=r'stale (instrument|actuator)'),
        C('sim_restart_clock_reset', 'sim restart',
          'sim restarts with its clock 100 s behind (stamps restart lower)', 'stale_safe',
          'restart', shift_stamp(-100.0), ticks=150, reason=r'stale (instrument|actuator)'),
    ]
    return cases


def _param_set_cases() -> list[FaultCase]:
    C = FaultCase
    return [
        C('set_max_current_read_only', 'runtime parameters', 'raise max_current to 5 A',
          'refuse_set', params={'max_current': 5.0}, reason=r'read.only'),
        C('set_max_current_slew_read_only', 'runtime parameters', 'raise max_current_slew to 1e4 A/s',
          'refuse_set', params={'max_current_slew': 1e4}, reason=r'read.only'),
        C('set_max_grip_force_read_only', 'runtime parameters', 'raise max_grip_force to 100 N',
          'refuse_set', params={'max_grip_force': 100.0}, reason=r'read.only'),
        C('set_control_rate_read_only', 'runtime parameters', 'change control_rate to 500 Hz',
          'refuse_set', params={'control_rate': 500.0}, reason=r'read.only'),
        C('set_negative_force_kp', 'runtime parameters', 'force_kp = -1 A/N',
          'refuse_set', params={'force_kp': -1.0}, reason=r'force_kp|range'),
        C('set_negative_jaw_ki', 'runtime parameters', 'jaw_ki = -5',
          'refuse_set', params={'jaw_ki': -5.0}, reason=r'jaw_ki|range'),
        C('set_force_ki_too_large', 'runtime parameters', 'force_ki = 1e6 (beyond its range)',
          'refuse_set', params={'force_ki': 1e6}, reason=r'force_ki|range'),
        C('set_watchdog_zero', 'runtime parameters', 'watchdog_timeout = 0 s (disables it)',
          'refuse_set', params={'watchdog_timeout': 0.0}, reason=r'watchdog_timeout|range'),
        C('set_wrong_type', 'runtime parameters', "force_kp = 'fast' (a string)",
          'refuse_set', params={'force_kp': 'fast'}, reason=r'type|force_kp'),
        C('set_unknown_object', 'runtime parameters', "object_kind = 'banana'",
          'refuse_set', params={'object_kind': 'banana'}, reason=r'banana|object_kind'),
        C('set_atomic_mixed', 'runtime parameters',
          'atomic set of a good gain and max_current = 5 A: all or nothing',
          'refuse_set', params={'force_kp': 0.02, 'max_current': 5.0}, reason=r'read.only'),
        C('set_grip_force_max_above_hardware', 'runtime parameters',
          'grip_force_max = 150 N (above the read-only max_grip_force), master fully closed',
          'bounded', params={'grip_force_max': 150.0}, master_angle=0.0),
    ]


def _param_file_cases() -> list[FaultCase]:
    C = FaultCase
    return [
        C('file_missing_parameters_section', 'parameter file',
          "a file whose node section has no 'ros__parameters'", 'refuse_start',
          params={'__text__': '/**:\n  max_current: 0.5\n'}, reason=r'ros__parameters|parameter'),
        C('file_not_yaml', 'parameter file', 'a file that is not YAML', 'refuse_start',
          params={'__text__': '/**: {ros__parameters: [unclosed\n'}, reason=r'param|yaml|pars'),
        C('file_missing_hardware_limit', 'parameter file',
          "an instrument file without 'max_current' (a hardware limit must be stated)",
          'refuse_start', params={'max_current': None}, reason=r'max_current'),
        C('file_wrong_type', 'parameter file', "max_current: 'lots'", 'refuse_start',
          params={'max_current': 'lots'}, reason=r'max_current'),
        C('file_out_of_range', 'parameter file', 'max_current: 50 A (range 0..20)',
          'refuse_start', params={'max_current': 50.0}, reason=r'max_current'),
        C('file_negative_gain', 'parameter file', 'force_kp: -1', 'refuse_start',
          params={'force_kp': -1.0}, reason=r'force_kp'),
        C('file_unknown_key', 'parameter file', "typo 'drum_raduis'", 'refuse_start',
          params={'drum_raduis': 0.004}, reason=r'drum_raduis'),
        C('file_inconsistent', 'parameter file', 'jaw_angle_min above jaw_angle_max',
          'refuse_start', params={'jaw_angle_min': 1.0, 'jaw_angle_max': 0.5},
          reason=r'jaw_angle_m'),
        C('file_nan_value', 'parameter file', 'max_current_slew: .nan', 'refuse_start',
          params={'max_current_slew': NAN}, reason=r'max_current_slew'),
        C('file_cable_overstressed', 'parameter file',
          'cable_radius 0.15 mm: the drum tension at max_current stresses it beyond its yield '
          'strength (an instrument that could not be built)', 'refuse_start',
          params={'cable_radius': 0.00015}, reason=r'could not be built.*cable stress'),
    ]


def dvrk_cases() -> list[FaultCase]:
    """Return the fault cases of the dVRK interface and the drive (kind 'process').

    They run on real node processes (:mod:`grip_force_ros.lab.faults.dvrk`).
    """
    C = FaultCase
    return [
        C('controller_sigkill_crtk', 'process', 'the controller process is killed (SIGKILL) '
          'mid-grasp, crtk profile', 'drive_cut', reason=r'command timeout'),
        C('controller_sigkill_dvrk', 'dvrk interface', 'the controller process is killed (SIGKILL) '
          'mid-grasp, dvrk profile', 'drive_cut', reason=r'command timeout'),
        C('arm_disabled_mid_grasp', 'dvrk interface', "state_command 'disable' to the arm "
          'mid-grasp', 'arm_interlock', reason=r'is DISABLED, not ENABLED'),
        C('current_on_effort_topic', 'dvrk interface', 'a current-sized number (0.3) on '
          'jaw/servo_jf, wrong units', 'effort_refused', reason=r'beyond the tool limit'),
        C('dvrk_master_silent', 'dvrk interface', 'the master MTML stops publishing (SIGSTOP) '
          'mid-grasp, dvrk profile', 'stale_safe', reason=r'stale master'),
    ]


def catalogue() -> list[FaultCase]:
    """Every fault case, message faults first."""
    cases = _message_cases() + _param_set_cases() + _param_file_cases() + dvrk_cases()
    names = [c.name for c in cases]
    if len(set(names)) != len(names):  # pragma: no cover - a programming error
        raise RuntimeError('duplicate fault case name')
    return cases


def select(cases: list[FaultCase], patterns: list[str] | None) -> list[FaultCase]:
    """Cases whose name or category contains any of ``patterns`` (all when None/empty)."""
    if not patterns:
        return list(cases)
    return [c for c in cases if any(p in c.name or p in c.category for p in patterns)]


def bad_params_text(base: dict[str, Any], edits: dict[str, Any]) -> str:
    """Compose the text of a ROS parameter file: ``base`` values with ``edits`` (None deletes a key).

    ``edits['__text__']`` replaces the whole file.
    """
    import yaml
    if '__text__' in edits:
        return edits['__text__']
    values = dict(base)
    for key, value in edits.items():
        if value is None:
            values.pop(key, None)
        else:
            values[key] = value
    body = {k: (list(v) if isinstance(v, tuple) else v) for k, v in values.items()}
    text = yaml.safe_dump({'/**': {'ros__parameters': body}}, sort_keys=False)
    return text
