"""The fault catalogue and its check against the real controller node.

ROS-free tests check the catalogue itself (kinds, outcomes, mutators). The ``ros`` tests run
whole catalogue against a real in-process controller node over loopback DDS (and the
controller executable for the parameter files), as ``grip-force faultcheck`` does (~20 s).
"""
import math

import pytest
from hypothesis import given, strategies as st

from grip_force_ros.lab.faults.catalogue import (OUTCOMES, SOURCES, bad_params_text, burst, catalogue,
                                                 duplicate_each, frozen_stamp, rename, resize, select,
                                                 set_field, shift_stamp, silence)
from grip_force_ros.params import SPECS

SAMPLE = {'stamp': 100.0, 'name': ['wrist_pitch', 'jaw'], 'position': [0.1, 0.2],
          'velocity': [0.0, 0.3], 'effort': []}


# ---------------------------------------------------------------------------- catalogue
def test_catalogue_has_25_kinds_with_defined_outcomes():
    cases = catalogue()
    assert len(cases) >= 25
    assert len({c.name for c in cases}) == len(cases)
    assert {c.outcome for c in cases} == set(OUTCOMES)
    categories = {c.category for c in cases}
    for needed in ('non-finite', 'array length', 'joint names', 'range', 'master range',
                   'timestamps', 'duplicates', 'burst', 'silence', 'sim restart',
                   'runtime parameters', 'parameter file'):
        assert needed in categories, needed
    for c in cases:
        assert c.description
        if c.kind in ('message', 'restart'):
            assert c.source in SOURCES + ('all', 'restart'), c.name
            assert c.ticks > 0
        if c.outcome in ('reject_safe', 'reject_once', 'stale_safe', 'clamp', 'refuse_set',
                         'refuse_start'):
            assert c.reason, f'{c.name}: an outcome with a reason needs the expected reason'
    # silence on every input topic, NaN and inf in every field the controller reads
    silenced = {c.source for c in cases if c.category == 'silence'}
    assert silenced == set(SOURCES)
    values = {c.name.split('_')[0] for c in cases if c.category == 'non-finite'}
    assert {'nan', 'inf', 'neg'} <= values


def test_mutators():
    assert set_field('position', 1, math.nan)(SAMPLE, 0)[0]['position'][1] != SAMPLE['position'][1]
    assert SAMPLE['position'] == [0.1, 0.2]          # the good sample is not modified
    assert resize('position', 1)(SAMPLE, 0)[0]['position'] == [0.1]
    assert resize('effort', 2)(SAMPLE, 0)[0]['effort'] == [0.0, 0.0]
    renamed = rename(['wrist_pitch', 'jaw', 'elbow'])(SAMPLE, 0)[0]
    assert renamed['name'][-1] == 'elbow' and len(renamed['position']) == 3
    assert shift_stamp(-1.0)(SAMPLE, 3)[0]['stamp'] == 99.0
    assert len(duplicate_each(3)(SAMPLE, 0)) == 3
    assert silence()(SAMPLE, 0) == []
    stamps = [s['stamp'] for s in burst(10)(SAMPLE, 0)]
    assert len(stamps) == 10 and stamps == sorted(stamps) and len(set(stamps)) == 10
    assert max(stamps) == pytest.approx(100.0) and min(stamps) > 99.999
    frozen = frozen_stamp()
    assert frozen(dict(SAMPLE, stamp=7.0), 9)[0]['stamp'] == 7.0     # a window starting at k 9
    assert frozen(dict(SAMPLE, stamp=8.0), 10)[0]['stamp'] == 7.0
    assert [frozen(dict(SAMPLE, stamp=t), k)[0]['stamp'] for k, t in enumerate((1.0, 2.0, 3.0))] \
        == [1.0, 1.0, 1.0]


def test_select():
    assert [c.name for c in select(catalogue(), ['silence_master'])] == ['silence_master']
    assert len(select(catalogue(), ['parameter file'])) == len(
        [c for c in catalogue() if c.kind == 'param_file'])
    assert [c.name for c in select(catalogue(), None)] == [c.name for c in catalogue()]


def test_steps_to_safe_reads_the_timeout_as_the_controller_does():
    """A step the controller took 0.1-0.2 us after its master watchdog expired counts as the
    first period after the timeout (fresh-clone CI read "period 0": the checker's float
    seconds were one ulp off the controller's, and its test was last + timeout < stamp)."""
    from types import SimpleNamespace

    from grip_force_ros.lab.faults.probe import FaultProbe
    from grip_force_ros.lab.faults.runner import _steps_to_safe
    case = select(catalogue(), ['silence_master'])[0]
    timeout = 0.1
    last_ns = 1_795_661_078_065_190_246                  # a receive time of that CI run (ns)
    last = last_ns * 1e-9                                 # the controller's clock: ns x 1e-9
    # the controller's first step past the timeout whose stamp the old reading put before it
    step_ns = next(n for n in range(last_ns + 100_000_000, last_ns + 100_010_000)
                   if n * 1e-9 - last > timeout
                   and n // 10 ** 9 + (n % 10 ** 9) * 1e-9 <= last + timeout)
    msg = SimpleNamespace(header=SimpleNamespace(stamp=SimpleNamespace(
        sec=step_ns // 10 ** 9, nanosec=step_ns % 10 ** 9)))
    stamp = FaultProbe._stamp(msg)
    assert stamp - last > timeout                         # the controller's own test
    before = (stamp - 0.001, 0.2, 1.0)                    # a gripping step 1 ms earlier
    rows = [(0.0, before[0], before[1], before[2]), (0.0, stamp, 0.0, 0.0)]
    assert _steps_to_safe(case, None, {'master': last}, rows, timeout) == 1


def test_a_spoiled_trial_is_redone_at_most_twice():
    """Two spoiled trials then a good one: the good one's detail; three spoiled: failed, with
    every cause in order (the fourth trial is never run)."""
    from grip_force_ros.lab.faults.catalogue import CASE_ATTEMPTS, redo_spoiled
    trials = iter([{'spoiled': 'a', 'passed': False}, {'spoiled': 'b', 'passed': False},
                   {'passed': True}])
    detail = redo_spoiled(lambda: next(trials), 'a stalled machine')
    assert detail['passed'] is True and detail['spoiled_trials'] == ['a', 'b']
    calls = []

    def always_spoiled():
        calls.append(1)
        return {'spoiled': f'stall {len(calls)}', 'passed': True}
    detail = redo_spoiled(always_spoiled, 'a stalled machine')
    assert len(calls) == CASE_ATTEMPTS == 3
    assert detail['passed'] is False
    assert detail['why'] == 'spoiled 3 times by a stalled machine: stall 1 | stall 2 | stall 3'


def test_a_safe_state_before_the_timeout_is_blamed_on_the_machine_only_for_a_stall_or_another_input():
    """A safe state before the silenced input's timeout, blamed on the machine or not.

    E.g. ``silence_master`` safe 87 ms after the last master sample (timeout 100 ms) because
    the test process held its GIL for 32-38 ms: the controller's reason is ``step interval
    36.2 ms > 30.0 ms (the controller was stalled)`` alone. A stall or another stale input
    spoils the trial (redone); the silenced input's own staleness, or a fault of the product,
    does not."""
    from grip_force_ros.lab.faults.runner import _machine_cause
    stall = 'controller | safe: step interval 36.2 ms > 30.0 ms (the controller was stalled)'
    other = 'controller | safe: stale instrument input: 32.7 ms old > 30.0 ms'
    own = 'controller | safe: stale master input: 100.5 ms old > 100.0 ms'
    limit = 'controller | safe: rejected actuator: measured current 1.107 A beyond +-1.100'
    assert _machine_cause([(1.0, stall, {})], ('master',), 1.1) == stall
    assert _machine_cause([(1.0, own, {}), (1.05, other, {})], ('master',), 1.1) == other
    assert _machine_cause([(1.0, own, {}), (1.0, limit, {})], ('master',), 1.1) is None
    assert _machine_cause([(1.0, other, {})], ('instrument', 'actuator'), 1.1) is None
    assert _machine_cause([(1.2, stall, {})], ('master',), 1.1) is None   # after the window


def test_a_watchdog_trial_is_spoiled_when_a_stall_not_its_own_input_made_the_output_safe():
    """``silence_actuator@sim_instrument`` safe in time but /diagnostics never saying 'stale
    actuator': a stall over the whole window, and the first step after it found a fresh
    actuator state. That trial measured nothing (redone); a
    missing reason with no machine cause, or a safe state before the timeout for a reason
    of the product, is the product's."""
    from grip_force_ros.lab.faults.runner import _watchdog_trial_spoiled
    stall = 'controller | safe: step interval 164.5 ms > 30.0 ms (the controller was stalled)'
    other = 'controller | safe: stale instrument input: 50.9 ms old > 30.0 ms'
    limit = 'controller | safe: rejected actuator: measured current 1.107 A beyond +-1.100'
    silenced = ('actuator',)
    # safe in time, its own reason seen: measured, whatever else happened
    assert _watchdog_trial_spoiled(1, True, [(1.0, stall, {})], silenced, 2.0) is None
    # safe in time but only for the stall (or another input): spoiled
    assert _watchdog_trial_spoiled(1, False, [(1.0, stall, {})], silenced, 2.0) == stall
    assert _watchdog_trial_spoiled(2, False, [(1.0, other, {})], silenced, 2.0) == other
    # safe before the timeout: spoiled by a stall, the product's fault otherwise
    assert _watchdog_trial_spoiled(0, True, [(1.0, stall, {})], silenced, 2.0) == stall
    assert _watchdog_trial_spoiled(0, True, [(1.0, limit, {})], silenced, 2.0) is None
    # the reason missing with no machine cause: the product's (not redone)
    assert _watchdog_trial_spoiled(1, False, [(1.0, limit, {})], silenced, 2.0) is None
    assert _watchdog_trial_spoiled(1, False, [(2.5, stall, {})], silenced, 2.0) is None   # later


@pytest.mark.ros
def test_a_stall_of_the_test_process_over_a_silence_window_spoils_the_trial_not_fails_it():
    """A machine stall, made on purpose: the test process (whose one executor thread
    runs the fault probe and the controller) sleeps 150 ms, 10 ms into a 120 ms silence of
    the ``sim_instrument`` process's actuator state. Such a trial is spoiled by the stall
    (and redone), not failed with "no /diagnostics text matching 'stale actuator'", and one
    whose controller still saw the actuator stale passes."""
    import time

    from grip_force_ros.lab.faults.runner import Session, run_message_case
    from grip_force_ros.params.files import instrument_path

    case = next(c for c in catalogue() if c.name == 'silence_actuator')
    session = Session(instrument_path(None), plant='sim_instrument')
    try:
        probe = session.probe
        relayed = probe._on_relayed
        window = {}

        def stalling(source, msg):
            if probe.fault and not window.get('stalled'):
                start = window.setdefault('start', time.monotonic())
                if time.monotonic() - start >= 0.010:
                    window['stalled'] = True
                    time.sleep(0.150)      # holds the executor thread: probe and controller
            return relayed(source, msg)

        probe._on_relayed = stalling
        outcomes = []
        for _ in range(2):
            window.clear()
            d = run_message_case(session, case)
            assert window.get('stalled'), 'the stall was not injected'
            if d['reason_seen'] is None:          # the controller never saw the actuator stale
                assert 'the controller was stalled' in (d.get('spoiled') or ''), d
            else:                                 # it did: the watchdog was measured
                assert d['passed'] and not d.get('spoiled'), d
            outcomes.append('spoiled' if d.get('spoiled') else 'passed')
        print('trials under a 150 ms stall:', outcomes)
    finally:
        session.close()


def test_the_main_threads_innermost_frame_is_read_from_faulthandler_output():
    from grip_force_ros.lab.faults.runner import main_thread_frame
    stacks = """Thread 0x00007f1 (most recent call first):
  File "/usr/lib/python3.11/threading.py", line 324 in wait
  File "/usr/lib/python3.11/threading.py", line 1002 in _bootstrap

Current thread 0x00007f0 (most recent call first):
  File "/x/rclpy/executors.py", line 713 in _wait_for_ready_callbacks
  File "/x/rclpy/__init__.py", line 244 in spin
  File "/x/lib/grip_force_ros/sim_instrument", line 33 in <module>
"""
    assert main_thread_frame(stacks) == 'File "/x/rclpy/executors.py", line 713 in _wait_for_ready_callbacks'
    assert main_thread_frame('no stacks here') == ''
    assert main_thread_frame(stacks.split('Current')[0]) == ''    # no main thread among them


def test_a_bad_parameter_file_case_whose_node_is_still_running_says_where_it_was(monkeypatch):
    """A controller on a bad file that has written nothing after 30 s: the case asks the
    process for its Python stacks before it kills it and says where its main thread was
    (here a stand-in that hangs in a function of its own)."""
    import sys

    from grip_force_ros.lab.faults import runner
    from grip_force_ros.params.files import instrument_path

    hangs = ('import faulthandler, signal, sys, time\n'
             'faulthandler.register(signal.SIGUSR1, all_threads=True)\n'
             'def stuck_starting():\n'
             '    time.sleep(60)\n'
             'print("starting", file=sys.stderr, flush=True)\n'
             'stuck_starting()\n')
    monkeypatch.setattr(runner, 'isolated_controller_command',
                        lambda path: [sys.executable, '-c', hangs])
    case = next(c for c in catalogue() if c.name == 'file_cable_overstressed')
    [detail] = runner.run_param_file_cases([case], instrument_path(None), timeout=5.0)
    assert not detail['passed'] and detail['exit_code'] is None
    assert 'in stuck_starting' in detail['main_thread_at_timeout'], detail
    assert 'still running after 5 s; its main thread in: File' in detail['why'], detail
    assert detail['stderr'] == 'starting'           # its own output, without the stacks
    assert runner.split_stacks('a\nb\n') == ('a\nb\n', '')
    assert runner.split_stacks('a\nThread 0x1 (most recent call first):\n  File "x"\n') == (
        'a\n', 'Thread 0x1 (most recent call first):\n  File "x"\n')


@pytest.mark.ros
def test_a_restarted_sim_that_runs_but_is_never_heard_spoils_the_trial_which_is_redone(monkeypatch):
    """The CI failure of ``sim_restart@sim_instrument`` (30 s with no state from the new
    process), made on purpose: the first new process publishes its states where the probe
    does not listen. The trial is spoiled with what the runner saw (the process alive, none
    publishers known on its topics, its main thread's frame), a new process replaces it, and
    the redone trial passes. A process that dies instead is the case's own failure."""
    from grip_force_ros.lab.faults import runner
    from grip_force_ros.lab.faults.probe import relay_remaps
    from grip_force_ros.lab.processes import NodeProcess, node_command
    from grip_force_ros.params.files import instrument_path

    monkeypatch.setattr(runner, 'PROCESS_READY_TIMEOUT', 8.0)
    case = next(c for c in catalogue() if c.name == 'sim_restart')
    session = runner.Session(instrument_path(None), plant='sim_instrument')
    try:
        start_sim = session._start_sim
        deaf = []

        def start_elsewhere():     # the first restart: a process the probe never hears
            if deaf:
                return start_sim()
            deaf.append(NodeProcess('sim_instrument', command=node_command(
                'sim_instrument', session.config, remaps=relay_remaps('/faultcheck_elsewhere')),
                log_path=session.sim.log_path))
            return deaf[0]

        monkeypatch.setattr(session, '_start_sim', start_elsewhere)
        detail = runner.run_case_redoing_spoiled(session, case)
        assert deaf and not deaf[0].alive(), 'the unheard process was not replaced'
        assert detail['passed'], detail
        assert len(detail['spoiled_trials']) == 1, detail
        cause = detail['spoiled_trials'][0]
        assert f'(pid {deaf[0].pid}) ran, but none of its states came in 8 s' in cause
        assert 'publishers on its 4 topics' in cause and 'in <module>' not in cause
        assert 'File "' in cause, cause      # its Python stacks were taken
        assert detail['sim_process']['states_relayed'] > 0 and detail['sim_process']['alive']
    finally:
        session.close()


def test_the_first_safe_step_is_found_by_the_controllers_stamp_up_to_the_recovery():
    """A 60 ms window that holds 12 steps, all gripping as received; the safe ones reach the
    probe after the window. What counts is what the controller did, by its own
    stamp, until it gripped again; a safe step after the recovery is another event."""
    from grip_force_ros.lab.faults.runner import _first_safe_step
    # (probe receive time, controller stamp, command, target)
    rows = [(10.001, 10.000, 0.3, 4.0), (10.070, 10.030, 0.2, 0.0), (10.071, 10.031, 0.2, 0.0),
            (10.080, 10.079, 0.3, 4.0), (10.500, 10.499, 0.0, 0.0)]
    assert _first_safe_step(rows, until=10.2) == 10.030
    assert _first_safe_step(rows[:1] + rows[3:], until=10.2) is None   # safe only after it
    assert _first_safe_step([], until=10.2) is None


def test_bad_params_text():
    import yaml
    base = {'max_current': 0.5, 'guide_pulley_radii': (0.003, 0.003)}
    doc = yaml.safe_load(bad_params_text(base, {'max_current': None, 'force_kp': -1.0}))
    values = doc['/**']['ros__parameters']
    assert 'max_current' not in values and values['force_kp'] == -1.0
    assert values['guide_pulley_radii'] == [0.003, 0.003]
    assert bad_params_text(base, {'__text__': 'x'}) == 'x'


def test_runtime_parameter_cases_name_schema_parameters():
    for c in catalogue():
        if c.kind == 'param_set':
            for name in c.params:
                assert name in SPECS, name
            if 'read_only' in c.name:
                assert all(SPECS[n].read_only for n in c.params)


# ---------------------------------------------------------------------------- real nodes
def _assert_report(report, n_cases):
    details = {d['name']: d for d in report['details']}
    failures = '\n'.join(f"{f['name']}: {f['why']}\n  detail: {details.get(f['name'])}"
                         for f in report['failures'])
    assert report['cases'] == n_cases
    assert report['crashes'] == 0, failures
    assert report['limit_violations'] == 0, failures
    assert report['passed'] == report['cases'], failures


@pytest.mark.ros
def test_faultcheck_whole_catalogue_on_real_nodes():
    """Every case against the real controller node, the cases that involve the instrument
    against the shipped sim_instrument process too, then the negative control (~1.5-2 min;
    grip-force faultcheck)."""
    from grip_force_ros.lab.faults.defects import DEFECTS
    from grip_force_ros.lab.faults.runner import involves_instrument, run_faultcheck
    report = run_faultcheck()
    on_process = [c.name for c in catalogue() if involves_instrument(c)]
    _assert_report(report, len(catalogue()) + len(on_process))
    by_name = {d['name']: d for d in report['details']}
    # every case that involves the instrument ran against the sim_instrument process as well
    assert len(on_process) >= 30
    for name in on_process:
        assert by_name[f'{name}@sim_instrument']['plant'] == 'sim_instrument'
    # "sim restart" there is a real one: the process killed (SIGKILL) and a new one started
    for name in ('sim_restart@sim_instrument', 'sim_restart_clock_reset@sim_instrument'):
        process = by_name[name]['sim_process']
        assert process['exit_code'] == -9 and process['new_pid'] != process['killed_pid']
        assert 1 <= by_name[name]['controller_steps_after_timeout'] <= 2, by_name[name]
    # negative control: every deliberately broken build is caught by at least one case
    negative = report['negative_control']
    assert negative['cases'] == len(DEFECTS) >= 4
    missed = [(d['defect'], d['missed_trials']) for d in negative['defects'] if not d['caught']]
    assert negative['caught'] == negative['cases'], f'defects not caught: {missed}'
    assert all(1 <= d['trials'] <= 3 for d in negative['defects']), negative['defects']
    assert {d['defect'] for d in negative['defects']} >= {'current_limit_off', 'slew_limit_off',
                                                          'watchdog_off', 'nan_passed_through'}
    # a load cell stuck at 0 N winds the force loop up to the current limit, which holds
    stuck = by_name['force_sensor_stuck_at_zero']
    assert stuck['peak_command'] == pytest.approx(stuck['max_current'], rel=1e-9)
    # the watchdog trips within two control periods after the timeout, on every input
    for name in ('silence_master', 'silence_instrument', 'silence_actuator',
                 'silence_force_sensor', 'frozen_stamp_actuator'):
        assert 1 <= by_name[name]['controller_steps_after_timeout'] <= 2, by_name[name]
    # faulty samples were counted as rejected; duplicates and bursts were not
    assert by_name['nan_master_gripper_angle']['rejected_samples'] > 0
    assert by_name['burst_10x_all']['rejected_samples'] == 0
    assert by_name['duplicate_master']['rejected_samples'] == 0
    # bounded: a grip force target above the hardware limit is capped
    capped = by_name['set_grip_force_max_above_hardware']
    assert 0 < capped['peak_target_force'] <= capped['max_grip_force']


def test_limit_monitor_counts_every_kind_of_violation():
    from grip_force_ros.lab.faults.probe import LimitMonitor
    m = LimitMonitor(max_current=0.5, max_step=0.1)
    for command in (0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.45, 0.35):   # within both limits
        m.check(command)
    assert m.violations == [] and m.count == 8
    m.check(0.5)          # +0.15 A: beyond the slew step
    m.check(0.6)          # beyond max_current
    m.check(math.nan)     # non-finite
    m.check(-0.6)         # beyond max_current, and a jump from the last finite command
    assert len(m.violations) == 4
    assert 'slew' in m.violations[0] and 'max_current' in m.violations[1]
    assert 'non-finite' in m.violations[2]


def test_limit_monitor_across_a_stall_of_its_own_process():
    """The probe's receipt times do not span a stall of its own process: the command that
    waited through it and the controller's first step after it arrive back to back. The
    step over the stall (from the measured current, by design) is judged on the controller's
    own step time, longer than the watchdog there: not bounded; max_current still holds, and
    the slew bound is back at the next step."""
    from grip_force_ros.lab.faults.probe import LimitMonitor
    m = LimitMonitor(max_current=0.5, max_step=0.1, period=0.001, max_period=0.03)
    # (controller clock at the step, command, receipt): the process stalled 35 ms after step 1
    steps = [(0.000, 0.30, 0.0002), (0.001, 0.30, 0.0350), (0.036, 0.00, 0.0351),
             (0.037, 0.10, 0.0361), (0.038, 0.00, 0.0371), (0.039, 0.60, 0.0381)]
    steps += [(0.001 * k + 0.034, 0.50, 0.001 * k + 0.0342) for k in range(6, 9)]
    for stamp, command, receipt in steps:
        m.check(command, t=receipt)
        m.note_step(receipt + 0.00005, stamp)
    assert len(m.violations) == 1 and 'max_current' in m.violations[0], m.violations
    m.check(0.20, t=0.0431)                  # -0.30 A in the controller's 1 ms step
    for k in range(9, 11):
        m.note_step(0.001 * k + 0.0342, 0.001 * k + 0.034)
    assert len(m.violations) == 2 and 'slew' in m.violations[1], m.violations


def test_a_jump_received_after_a_gap_is_judged_on_the_controllers_step():
    """A missing slew limit jumps max_current -> 0 A in one 1 ms step at the safe state; the
    probe, stalled, receives it 40 ms after the command before. Receipt gaps cannot excuse
    it: only the controller's own step time can (else the negative control misses
    slew_limit_off)."""
    from grip_force_ros.lab.faults.probe import LimitMonitor
    m = LimitMonitor(max_current=0.5, max_step=0.1, period=0.001, max_period=0.03)
    steps = [(0.001 * k, 0.5, 0.001 * k + 0.0002) for k in range(5)]
    steps += [(0.005, 0.0, 0.045), (0.006, 0.0, 0.0451), (0.007, 0.0, 0.0452)]
    for stamp, command, receipt in steps:
        m.check(command, t=receipt)
        m.note_step(receipt + 0.00005, stamp)
    assert len(m.violations) == 1, m.violations
    assert '-0.500000' in m.violations[0] and 'step that sent it 1.00 ms' in m.violations[0]


def test_a_change_across_lost_commands_is_judged_on_the_steps_they_were():
    """CI of c68dacc: pytest's process stalled ~0.3 s, its reader fell behind and lost the
    controller's ramp (0.29 -> 0.19 -> 0.09 -> 0 A at 100 A/s), and the judge saw 0.29 -> 0 A
    in one 1 ms step. Each step publishes its command, then its target force: steps received
    between two commands are commands lost, and a change across n of them spans n + 1 steps.
    A jump bigger than the steps lost allow is still caught."""
    from grip_force_ros.lab.faults.probe import LimitMonitor

    def judged(jump_to, lost_steps_received=True):
        m = LimitMonitor(max_current=0.5, max_step=0.1, period=0.001, max_period=0.03)
        # one control step a ms; from step 4 on received 0.293 s late (a backlog), and the
        # commands of steps 4-6 (the ramp) never: their target forces (the steps) do arrive,
        # unless lost_steps_received is False
        for k in range(130):
            stamp = 0.001 * k                                      # the controller's clock (s)
            receipt = stamp + (0.0002 if k < 4 else 0.293)
            if k < 4 or k > 6:
                m.check(0.29 if k < 4 else jump_to if k == 7 else 0.0, t=receipt)
            if lost_steps_received or not 4 <= k <= 6:
                m.note_step(receipt + 0.00005, stamp)
        return m.violations, m.commands_missed

    assert judged(0.0) == ([], 3)                                   # 3 lost: 4 steps, 0.4 A
    # the steps lost too: the interval between the steps received around the gap spans them
    assert judged(0.0, lost_steps_received=False) == ([], 0)
    # -0.79 A across the gap: beyond 4 steps; and +0.5 A back to 0 A in one step
    runaway, missed = judged(-0.5)
    assert missed == 3 and len(runaway) == 2 and 'across 3 lost commands' in runaway[0], runaway


@given(st.lists(st.booleans(), min_size=30, max_size=300), st.integers(2, 29), st.booleans())
def test_a_ramp_at_the_slew_limit_passes_whatever_commands_are_lost_and_a_jump_does_not(
        received, jump_at, steps_lost_too):
    """A controller ramping up and down at its slew limit (0.1 A a 1 ms step, between -0.4 and
    0.4 A), the probe receiving any subset of its commands (and, or not, of their steps): no
    violation. The same with one step of +0.6 A at ``jump_at``: a violation, whatever else was
    lost, as long as the jump and the two steps either side of it were received (the judge
    bounds a change by the longest of the controller's steps around it)."""
    from grip_force_ros.lab.faults.probe import LimitMonitor

    def run(jump):
        m = LimitMonitor(max_current=2.0, max_step=0.1, period=0.001, max_period=0.03)
        for k, got in enumerate(received):
            level = 4 - abs(k % 16 - 8)                       # -4..4 tenths of an A, +-1 a step
            command = 0.1 * level + (0.6 if jump and k == jump_at else 0.0)
            stamp = 0.001 * k
            keep = got or k == 0 or (jump and jump_at - 2 <= k <= jump_at + 2)
            if keep:
                m.check(command, t=stamp + 0.0002)
            if keep or not steps_lost_too:
                m.note_step(stamp + 0.00025, stamp)
        return m.violations

    assert run(jump=False) == []
    assert any('beyond the slew limit' in v for v in run(jump=True))


def test_a_slew_step_is_judged_on_the_controllers_own_step_time():
    """Receipt gaps can be shorter than the controller's step (commands that waited in the
    probe's queue while a slow callback held the shared thread): a step beyond the receipt
    bound is a violation only if the controller's step that sent it was not long enough."""
    from grip_force_ros.lab.faults.probe import LimitMonitor
    m = LimitMonitor(max_current=0.5, max_step=0.1, period=0.001, max_period=0.03)
    # (controller clock at the step, command, its receipt): step 2 came 4 ms after step 1,
    # and step 1's command waited in the queue until just before it
    steps = [(0.000, 0.10, 0.0002), (0.001, 0.10, 0.0051), (0.005, 0.46, 0.0053),
             (0.006, 0.40, 0.0062), (0.007, 0.10, 0.0072)]
    steps += [(0.001 * k + 0.003, 0.10, 0.001 * k + 0.0032) for k in range(5, 10)]
    for stamp, command, receipt in steps:
        m.check(command, t=receipt)
        m.note_step(receipt + 0.00005, stamp)   # its target force, right after the command
    # +0.36 A over the controller's 4 ms step: within 100 A/s; -0.30 A in a 1 ms step: not
    assert len(m.violations) == 1, m.violations
    assert '-0.300000' in m.violations[0] and 'step that sent it 1.00 ms' in m.violations[0]


def test_time_message_conversion():
    from grip_force_ros.lab.faults.probe import to_time_msg
    t = to_time_msg(12.25)
    assert (t.sec, t.nanosec) == (12, 250_000_000)
    assert to_time_msg(-5.0).sec == 0                     # clamped to the message's range
    assert to_time_msg(1e12).sec == 2 ** 31 - 1


class _RecordingPublisher:
    """Stands in for a probe publisher: keeps the stamp of every message as it was published."""

    def __init__(self):
        self.stamps = []

    def publish(self, msg):
        self.stamps.append(msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9)


@pytest.mark.ros
def test_probe_restamps_one_message_per_burst_and_ticks_when_its_timer_is_late():
    """The probe builds a burst's message once (10 publishes, 10 stamps), and a relayed state
    runs the probe's tick when the timer is a period late: otherwise the master goes 100 ms
    stale behind the probe's own relayed 10 kHz burst on a loaded machine
    (burst_10x_all@sim_instrument)."""
    import os

    import rclpy
    from rclpy.context import Context
    from sensor_msgs.msg import JointState

    from grip_force_ros.lab.faults.probe import FaultProbe, to_time_msg
    from grip_force_ros.params import load_params_file
    from grip_force_ros.params.files import instrument_path

    ctx = Context()
    rclpy.init(context=ctx, domain_id=int(os.environ['ROS_DOMAIN_ID']))
    try:
        probe = FaultProbe(load_params_file(instrument_path(None)), context=ctx,
                           relay='/test_relay')
        probe.timer.cancel()                       # the test drives the probe by hand
        clock = [1000.0]                           # and its clock (s): a loaded machine can
        probe.now = lambda: clock[0]               # take over a period between two lines
        out = probe._pubs['instrument'] = _RecordingPublisher()
        master = probe._pubs['master'] = _RecordingPublisher()
        built = []
        message = FaultProbe._message
        probe._message = lambda source, s: built.append(source) or message(source, s)
        probe.inject(('instrument', 'master'), burst(10), ticks=5)
        state = JointState(name=['wrist_pitch', 'jaw'], position=[0.1, 0.2], velocity=[0.0, 0.3])
        state.header.stamp = to_time_msg(100.0)
        probe.last_tick = clock[0]                 # the timer has just ticked: relay only
        probe._on_relayed('instrument', state)
        assert built == ['instrument']             # one message for the ten samples
        assert out.stamps == pytest.approx([99.9991 + 0.0001 * i for i in range(10)], abs=1e-8)
        assert probe.ticks == 0 and master.stamps == []
        clock[0] += 2 * probe.period               # the timer is late: the relay ticks
        probe._on_relayed('instrument', state)
        assert probe.ticks == 1 and len(master.stamps) == 10   # the master burst went out
        assert len(set(out.stamps)) == 10          # the same ten stamps again: restamped
        probe._on_relayed('instrument', state)     # not a period later: no second tick
        assert probe.ticks == 1
        probe._on_timer()                          # the late timer event itself: no tick
        assert probe.ticks == 1
        clock[0] += probe.period
        probe._on_timer()                          # a period on: the timer ticks
        assert probe.ticks == 2
        probe.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)


@pytest.mark.ros
def test_faultcheck_cli_json():
    """``grip-force faultcheck --only ... --json`` prints the report; exit 0 when all pass."""
    import json
    import subprocess
    import sys
    cmd = [sys.executable, '-m', 'grip_force_ros.lab.cli', 'faultcheck', '--json', '--only',
           'silence_actuator', 'set_max_current_read_only', 'file_out_of_range']
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    report = json.loads(done.stdout)
    assert {k: report[k] for k in ('cases', 'passed', 'crashes', 'limit_violations', 'failures')} \
        == {'cases': 4, 'passed': 4, 'crashes': 0, 'limit_violations': 0, 'failures': []}
    assert sorted(d['name'] for d in report['details']) == sorted(
        cmd[-3:] + ['silence_actuator@sim_instrument'])
    assert report['negative_control'] == {'cases': 0, 'caught': 0, 'defects': []}   # --only


def test_a_defect_cannot_be_injected_outside_the_negative_control():
    """The test-only switch: no broken build outside the fault check's own session."""
    from grip_force_ros.lab.faults.defects import DEFECTS, break_controller, negative_control_session
    from grip_force_ros.nodes.controller_io import read_joints
    with pytest.raises(RuntimeError, match='negative control'):
        break_controller(object(), 'watchdog_off')
    with negative_control_session(), pytest.raises(ValueError, match='unknown defect'):
        break_controller(object(), 'brakes_off')
    for defect in DEFECTS.values():           # each names cases of the catalogue
        assert defect.cases and set(defect.cases) <= {c.name for c in catalogue()}
    from grip_force_ros.nodes import controller_io as node_module
    assert node_module.read_joints is read_joints     # nothing left patched
