"""Watchdog timing and read-only hardware limits on real nodes.

An in-process controller node (parameter overrides from the paper's needle driver YAML)
and a fault probe that closes the loop with a simulated instrument over loopback DDS
(:class:`grip_force_ros.lab.faults.runner.Session`).

Watchdog: each input in turn falls silent; the first safe output (target force 0 N, the
current ramping to 0 A) must come within two control periods after its own timeout (30 ms
for the instrument joints and the actuator, as the dVRK's drive link; 100 ms for the master
console stream) has expired on the controller's clock, and when the input returns
control resumes without a current jump. The wall-clock time from the last published input
to the first safe command is measured too (it includes DDS delivery and the scheduling of
a loaded 2-core machine); its median is asserted, every trial is printed (``pytest -s``).
"""
import statistics

import pytest

from grip_force_ros.control.inputs import source_timeouts
from grip_force_ros.lab.faults.catalogue import CASE_ATTEMPTS, FaultCase, set_field, silence
from grip_force_ros.lab.faults.runner import Session, run_case_redoing_spoiled, run_message_case
from grip_force_ros.params.files import instrument_path

pytestmark = pytest.mark.ros

TRIALS = 4   # per silenced input


@pytest.fixture(scope='module')
def session():
    s = Session(instrument_path('config/paper_needle_driver.yaml'))
    assert s.wait_gripping(), 'the controller did not start gripping'
    yield s
    s.close()


def _silence(source, ticks=None, params=None):
    """Silence ``source`` for ``ticks`` ms (default: its own watchdog timeout + 50 ms)."""
    if ticks is None:
        ticks = int(round(source_timeouts(params)[source] * 1e3)) + 50
    return FaultCase(f'silence_{source}', 'silence', f'no {source} messages', 'stale_safe',
                     source, silence(), ticks=ticks, reason=f'stale {source}')


def test_watchdog_safe_within_two_periods_and_bumpless_resume(session):
    params = session.params
    period = 1.0 / params.control_rate
    timeouts = source_timeouts(params)
    assert timeouts['instrument'] == timeouts['actuator'] == pytest.approx(0.030)   # the dVRK's
    assert timeouts['master'] == pytest.approx(0.1) and period == pytest.approx(1e-3)
    step = params.max_current_slew * period
    latencies, received, jumps = [], [], []
    for source in ('master', 'instrument', 'actuator'):
        timeout = timeouts[source]
        for trial in range(TRIALS):
            d = run_case_redoing_spoiled(session, _silence(source, params=params))
            print(f"{source} #{trial}: safe {d['safe_after_last_input_ms']} ms after the last "
                  f"publish, {d['safe_after_last_receive_ms']} ms after its receipt, "
                  f"period {d['controller_steps_after_timeout']} after the timeout, "
                  f"resume jump {d['max_resume_jump'] * 1e3:.3f} mA")
            assert d['passed'], d
            assert 1 <= d['controller_steps_after_timeout'] <= 2, (
                f"{source} #{trial}: safe at period {d['controller_steps_after_timeout']} after the "
                f"timeout, {d['safe_after_last_receive_ms']} ms after the last receipt; "
                f"safe-state reason: {d.get('safe_before_timeout')}")
            # the receive-time latency is bounded by the controller's own steps: it trips on
            # age > timeout at a step, so the latency exceeds the timeout by up to a period and
            # by as little as a few us (the phase of the steps); the detail is rounded to 1 us
            # (30.0 was read under load)
            assert d['safe_after_last_receive_ms'] >= timeout * 1e3 - 1e-3
            assert d['watchdog_timeout_ms'] == pytest.approx(timeout * 1e3)
            # beyond the timeout: the latency from the last publish, less the source's timeout
            latencies.append(d['safe_after_last_input_ms'] / 1e3 - timeout)
            received.append(d['safe_after_last_receive_ms'] / 1e3 - timeout)
            jumps.append(d['max_resume_jump'])
    print(f'last publish -> first safe command, beyond the timeout: median '
          f'{statistics.median(latencies) * 1e3:.2f} ms, max {max(latencies) * 1e3:.2f} ms over '
          f'{len(latencies)} trials')
    assert statistics.median(received) <= 2 * period + 1e-4
    assert statistics.median(latencies) <= 2 * period + 2e-3   # + DDS delivery
    # bumpless: the first command after the safe state continues from the last one
    assert max(jumps) <= 0.5 * step


def test_resume_from_a_partial_ramp_has_no_current_jump(session):
    """Inputs back after 31 ms of silence, or one NaN sample: the ramp to 0 A is under way
    (0.1 A per period) when control resumes; the command continues where the ramp left it."""
    params = session.params
    step = params.max_current_slew / params.control_rate
    # the master fully closed (4 N): the hold current (~0.2-0.3 A) is more than one slew step
    # (0.1 A), so a resume can come mid-ramp; at the default 2 N the stick band's middle
    # branch holds with ~0.1 A, which one safe period ramps to 0 A
    single_nan = FaultCase('single_nan_jaw', 'non-finite', 'one NaN jaw angle', 'reject_once',
                           'instrument', set_field('position', 1, float('nan')), ticks=1,
                           reason='nan', master_angle=0.0)
    silent = FaultCase('silence_instrument', 'silence', 'no instrument messages', 'stale_safe',
                       'instrument', silence(), ticks=31, reason='stale instrument',
                       master_angle=0.0)
    resumed_from = []
    # a loaded machine can let every ramp finish before the inputs are back (all six resumes
    # from 0 A): the six trials are redone, at most twice, until
    # one resume comes mid-ramp; every trial's resume is checked for bumps all the same
    for _ in range(CASE_ATTEMPTS):
        for case in (silent, single_nan) * 3:
            d = run_message_case(session, case)
            # one bad sample or 31 ms of silence need not make a safe period (the next good
            # sample may come first); when one happened, the resume must be bumpless
            assert d['recovered'] and d['limit_violations'] == 0, d
            assert d['max_resume_jump'] <= 0.5 * step, d
            rows = session.probe.steps                  # (recv, stamp, command, target)
            for (_, _, c0, f0), (_, _, c1, f1) in zip(rows, rows[1:]):
                if f0 == 0.0 and f1 > 0.0:
                    resumed_from.append(abs(c0))
        if any(i > 0.01 for i in resumed_from):
            break
    print('resumed from |I| =', resumed_from)
    assert any(i > 0.01 for i in resumed_from), \
        f'no resume mid-ramp in {CASE_ATTEMPTS} rounds (every ramp ended first): {resumed_from}'


def test_safe_output_ramps_at_the_slew_limit(session):
    """While safe, the current falls to 0 A at the slew limit, never faster.

    The controller steps on the time it measured between states, which the probe sees as
    the gaps between the commands' receipts and stamps (plus one period of delivery jitter:
    lab/faults/probe.py); the exact per-step check is test/test_control_properties.py.
    """
    from grip_force_ros.lab.faults.probe import DELIVERY_JITTER
    probe, params = session.probe, session.params
    period = 1.0 / params.expected_state_rate
    d = run_message_case(session, _silence('instrument', ticks=60))
    assert d['passed'], d
    # the commands of the safe stretch: |I| decreasing to 0 A, by at most the slew over the time
    safe = [(t, stamp, command) for t, stamp, command, target in probe.steps if target == 0.0]
    assert safe, 'no safe output recorded'
    for (t0, s0, a), (t1, s1, b) in zip(safe, safe[1:]):
        dt = max(t1 - t0, s1 - s0, period) + DELIVERY_JITTER * period
        assert abs(b) <= abs(a) + 1e-12 and abs(a - b) <= params.max_current_slew * dt * (1 + 1e-9)
    safe = [command for _, _, command in safe]
    assert abs(safe[-1]) < 1e-9     # 60 ms of silence: reached 0 A (<= 0.5 A at 0.1 A/ms)
    assert probe.limits.violations == []


@pytest.mark.parametrize('name, value', [
    ('max_current', 5.0), ('max_current_slew', 1e4), ('max_grip_force', 100.0),
    ('jaw_angle_max', 3.0), ('wrist_angle_limit', 3.0), ('control_rate', 500.0)])
def test_hardware_limits_are_read_only_and_say_why(session, name, value):
    before = session.get_parameter(name)
    (ok, reason), = session.set_parameters({name: value})
    assert not ok
    assert 'read-only' in reason or 'read only' in reason, reason
    assert name in reason or 'read-only' in reason
    assert session.get_parameter(name) == before


@pytest.mark.parametrize('values, words', [
    ({'force_kp': -1.0}, ('force_kp', '-1.0', 'range')),
    ({'watchdog_timeout': 5.0}, ('watchdog_timeout', 'range')),
    ({'grip_force_max': float('nan')}, ('grip_force_max',)),
    ({'object_kind': 'banana'}, ('banana', 'object_kind')),
])
def test_unsafe_runtime_sets_are_refused_with_the_reason(session, values, words):
    before = {k: session.get_parameter(k) for k in values}
    results = session.set_parameters(values)
    assert [ok for ok, _ in results] == [False] * len(values)
    reason = results[0][1]
    for word in words:
        assert word in reason, (word, reason)
    after = {k: session.get_parameter(k) for k in values}
    assert after == before
    # the loop still grips after the refusal
    assert session.wait_gripping(2.0)
