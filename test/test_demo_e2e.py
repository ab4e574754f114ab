"""grip-force demo end to end: real node processes over loopback DDS, a short needle grasp."""
import importlib.util
import json
import os
import subprocess
import sys

import pytest

from grip_force_ros import topics

NODES = ('controller', 'sim_instrument', 'master')
pytestmark = [
    pytest.mark.ros, pytest.mark.slow,
    pytest.mark.skipif(any(importlib.util.find_spec(f'grip_force_ros.nodes.{n}') is None
                           for n in NODES), reason='the node executables are not built yet'),
]


#: Sensorless hold on a plant that matches its YAML (the demo's default): the load cell's
#: mean may differ from the target by the model's residual, expected within ~2 % (the
#: closed loop on the same sim without ROS: +1.0 %, docs/control.md; test_ros_nodes: -1.6
#: to +0.2 %), bound 3 %: the stick band's state can be 1-3 % off after a move, and this
#: 4 s task moves 2.5x faster than the 10 s default. RMS: that mean plus the load cell's
#: own noise (0.02 N = 0.5 % of 4 N) and the ripple the current noise (2 mA) makes through
#: dF/dI ~ 14 N/A (0.03 N = 0.7 %): sqrt(3^2 + 0.5^2 + 0.7^2) % = 3.1 %, bound 4 %.
HOLD_MEAN_TOLERANCE = 0.03
HOLD_RMS_TOLERANCE = 0.04
#: Pull-out force = (sqrt(2) + 1) mu' x the grip estimate (the paper's needle held in three
#: points, mu' = 0.15): 0.362 x 4 N = 1.45 N while the master holds the target; 5 % for the
#: estimate's excursions at the pull phase's start (the estimate holds within 1 % after).
PULL_OUT_TOLERANCE = 0.05

#: A run spoiled in its hold phase (an input lost for longer than its watchdog timeout, or a
#: topic silent for 100 ms: docs/demo.md) is redone at most twice; a third spoiled run fails
#: the hold test with the causes of all three. A late input (control went on) spoils nothing.
ATTEMPTS = 3


@pytest.fixture(scope='module')
def demo_run(tmp_path_factory):
    """(output folder, result JSON, problems of each spoiled attempt) of the last run."""
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    spoiled = []
    for attempt in range(ATTEMPTS):
        out = tmp_path_factory.mktemp('demo')
        proc = subprocess.run([sys.executable, '-m', 'grip_force_ros.lab.cli', 'demo', '--duration',
                               '4', '--json', '--quiet', '--out', str(out)],
                              capture_output=True, text=True, timeout=120, env=env)
        assert proc.returncode == 0, proc.stderr[-3000:]
        result = json.loads(proc.stdout)
        if not result['problems']:
            break
        spoiled.append(f"attempt {attempt + 1}: {'; '.join(result['problems'])} (load average "
                       f'{os.getloadavg()[0]:.1f})')
    return out, result, spoiled


def test_bag_holds_every_topic_and_rosbags_reads_it(demo_run):
    from rosbags.highlevel import AnyReader
    out, result, _ = demo_run
    bag = out / 'bag'
    assert result['bag'] == str(bag) and (bag / 'metadata.yaml').exists()
    with AnyReader([bag]) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        first = next(reader.messages())
        reader.deserialize(first[2], first[0].msgtype)
    # the sim sends its state combined (state_message): no actuator topic of its own
    assert set(counts) == {'/' + t.lstrip('/') for t in topics.RECORDED
                           if t != topics.ACTUATOR_JS}
    assert all(counts[t] > 0 for t in counts), counts
    # the 1 kHz streams over the whole task: ~4000-6000 states and commands on a quiet machine
    # (the task and its start and tail), fewer when the nodes are starved (2052 states, 1867
    # commands at load 14: the sim then steps longer periods, states overtake each other;
    # or more commands than states, 4435 vs 2508, when the controller's fallback timer
    # answers late states). Reported, not judged; the recording is: at least 100 a second.
    print(f"recorded in a {result['duration']:.1f} s task: {counts} "
          f'(load average {os.getloadavg()[0]:.1f})')
    for stream in ('/instrument/measured_js', '/instrument/actuator/servo_jf',
                   '/grip/target_force'):
        assert counts[stream] > 100 * result['duration'], (stream, counts)


def test_plot_and_results_are_written(demo_run):
    out, result, _ = demo_run
    plot = out / 'summary.png'
    assert result['plot'] == str(plot)
    assert plot.read_bytes()[:4] == b'\x89PNG' and plot.stat().st_size > 30_000
    assert json.loads((out / 'results.json').read_text())['metrics'] == result['metrics']
    assert set(result['phases']) == {'approach', 'close', 'hold', 'pull', 'release'}
    # every node stopped cleanly (master on its own, the others on SIGINT)
    # (one that had to be killed wrote its threads' stacks to its log first: shown here)
    assert result['exit_codes'] == {'sim_instrument': 0, 'controller': 0, 'master': 0}, {
        name: (out / 'logs' / f'{name}.log').read_text(errors='replace')[-4000:]
        for name, code in result['exit_codes'].items() if code != 0}
    # the 1 kHz nodes under SCHED_FIFO 50 where permitted, the master ten below them
    sched = result['scheduling']
    if sched['controller'] == 'SCHED_FIFO 50':
        assert sched['sim_instrument'] == 'SCHED_FIFO 50' and sched['master'] == 'SCHED_FIFO 40'
    else:                       # not permitted here: all three normal, and it says why
        assert all('not permitted' in v for v in sched.values()), sched


def test_hold_force_reaches_the_target(demo_run):
    _, result, spoiled = demo_run
    assert not result['problems'], f'{ATTEMPTS} demo runs spoiled: ' + ' | '.join(spoiled)
    # late inputs and safe-state entries are reported apart; none of the latter in this run
    assert set(result['late_inputs']) >= {'total'} and result['metrics']['late_inputs'] >= 0
    hold = result['phases']['hold']
    assert not [e for e in result['safe_state_entries'] if hold[0] <= e['t'] <= hold[1]]
    m = result['metrics']
    assert m['target_force'] == pytest.approx(4.0)               # N: grip_force_max, master closed
    assert abs(m['hold_error_mean']) < HOLD_MEAN_TOLERANCE * m['target_force'], m
    assert m['hold_error_rms'] < HOLD_RMS_TOLERANCE * m['target_force'], m
    expected_pull_out = (2 ** 0.5 + 1) * 0.15 * m['target_force']
    assert m['pull_out_force'] == pytest.approx(expected_pull_out, rel=PULL_OUT_TOLERANCE), m


def test_ctrl_c_stops_every_node(tmp_path):
    """SIGINT to the demo mid-task: it exits 130 and leaves no node process behind."""
    import signal
    import time

    import psutil
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    # A suite started as a background job (`./dev test ... &`, nohup, CI runners) inherits
    # SIGINT ignored, and Python then keeps it ignored: the demo would run its whole task
    # (exit 0 after ~30 s). The demo gets SIGINT's default, as in a terminal.
    demo = subprocess.Popen([sys.executable, '-m', 'grip_force_ros.lab.cli', 'demo', '--duration',
                             '20', '--quiet', '--out', str(tmp_path / 'run')],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        deadline = time.monotonic() + 60
        children = []
        while time.monotonic() < deadline and len(children) < 3:
            children = psutil.Process(demo.pid).children(recursive=True)
            time.sleep(0.2)
        assert len(children) >= 3, 'the three nodes never started'
        names = [' '.join(c.cmdline()[:2]) for c in children if c.is_running()]
        time.sleep(2.0)
        sent = time.monotonic()
        demo.send_signal(signal.SIGINT)
        try:
            out, err = demo.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            demo.kill()
            out, err = demo.communicate()
    finally:
        if demo.poll() is None:
            demo.kill()
    assert demo.returncode == 130, (
        f'exit {demo.returncode} {time.monotonic() - sent:.1f} s after SIGINT; children {names}; '
        f'stderr: {err[-1500:]!r}; stdout: {out[-1500:]!r}')
    assert 'interrupted' in err
    gone, alive = psutil.wait_procs(children, timeout=5)
    assert not alive, [p.pid for p in alive]


def test_demo_through_the_dvrk_interface(tmp_path):
    """``grip-force demo --interface dvrk``: the sim plays PSM1, the master is MTML, the
    controller enables and homes the arm and holds the grasp through the jaw effort (N*m)."""
    from _ros_tools import require_ros_tools
    from rosbags.highlevel import AnyReader
    require_ros_tools()
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    for attempt in range(ATTEMPTS):
        out = tmp_path / f'run{attempt}'
        proc = subprocess.run([sys.executable, '-m', 'grip_force_ros.lab.cli', 'demo', '--interface',
                               'dvrk', '--duration', '4', '--json', '--quiet', '--out', str(out)],
                              capture_output=True, text=True, timeout=180, env=env)
        assert proc.returncode == 0, proc.stderr[-3000:]
        result = json.loads(proc.stdout)
        if not result['problems']:
            break
    assert (result['interface'], result['arm'], result['master']) == ('dvrk', 'PSM1', 'MTML')
    assert result['exit_codes'] == {'sim_instrument': 0, 'controller': 0, 'master': 0}
    with AnyReader([out / 'bag']) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
    names = topics.topic_set('dvrk', 'PSM1', 'MTML')
    # the controller's default dvrk_command is effort: jaw/servo_jf, no jaw/servo_jp
    want = {'/' + t.lstrip('/') for t in names.recorded()
            if t not in (names.operating_state, names.jaw_servo_jp)}
    assert set(counts) == want, counts
    # the dVRK's 100 Hz over a 4 s task (plus start-up and tail)
    assert 350 < counts['/PSM1/jaw/measured_js'] < 2000, counts
    assert counts['/PSM1/jaw/servo_jf'] > 300, counts
    # at 100 Hz a loaded machine does not starve the loop: no retry may be spoiled three times
    assert not result['problems'], result['problems']
    m = result['metrics']
    assert m['target_force'] > 1.0
    # 100 Hz states: the offline rate table's hold error is within 3 % (docs/control.md); 10 %
    # leaves room for the sim's noise and a loaded machine, as the crtk demo test does
    assert abs(m['hold_error_mean']) < 0.1 * m['target_force']
    assert m['pull_out_force'] > 0.0
