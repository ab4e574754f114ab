"""The 1 kHz loop over DDS: the middleware floor and the product, side by side.

* :func:`run_floor`: bare rclpy ping-pong between two processes (:mod:`.child`
  ``ping`` and ``echo``), the product's message types, one variant of the
  settings (executor, QoS depth, gc.freeze, preallocated messages, callback groups).
  The floor sends one state message a period; the *contract floor*
  (``Variant.sensors``) sends the topic contract's two (the load cell, then one
  combined joint state: wrist_pitch, jaw, jaw_drum), so that what the contract costs
  and what this package's code costs are told apart.
* :func:`run_product`: the shipped ``master`` executable, the shipped sim node
  (measuring its own loop, :mod:`.product_sim`) and the shipped controller node
  (noting the input stamps of each step, :mod:`.product_controller`) with an
  instrument YAML, sensorless as shipped or with the load cell in the loop;
  :func:`run_products` runs several such arms at once (``/PSM1``, ``/PSM2``: one ROS
  namespace each, one domain, one window), and :func:`compare_arms` judges each against
  the one floor of the run. A product is judged against the floor that carries its
  messages: the sensorless controller (one state message a period) against the floor,
  the load-cell controller (two) against the contract floor.

Both are measured by the process that publishes the state, on its own clock:
the answer carries the stamp of the state it answers. Both return the same
structure: ``latency`` (p50/p99/max round trip, ms), ``periods`` (periods whose
state got no answer), ``timer_periods`` (gaps of the state publisher's 1 kHz
timer), ``cpu_percent`` (% of one core per process), plus what is particular to each:
the product's ``full_path`` (sensing to actuation: from the sample of every input a
step used to the command's arrival, :func:`~grip_force_ros.lab.bench.stats.full_path`).
"""
from __future__ import annotations

import json
import math
import tempfile
import time
from dataclasses import asdict, dataclass, replace

import numpy as np

from grip_force_ros.lab.bench.procs import BenchError, Child, stop_all
from grip_force_ros.lab.bench.stats import full_path, ratio
from grip_force_ros.lab.processes import node_executable, python_module, ros_args, ros_environment
from grip_force_ros.params.files import instrument_path

CHILD = 'grip_force_ros.lab.bench.child'
#: Longest wait for discovery plus warm-up before a window opens (s).
START_TIMEOUT = 60.0


@dataclass(frozen=True)
class Variant:
    """Settings of the rclpy processes of one floor run.

    Attributes
    ----------
    executor : str
        'events' (``rclpy.experimental.EventsExecutor``), 'single'
        (``SingleThreadedExecutor``) or 'multi' (``MultiThreadedExecutor``, 2 threads).
    depth : int
        QoS KEEP_LAST depth of the state and command topics.
    gc_freeze : bool
        ``gc.collect(); gc.freeze()`` once start-up is over.
    prealloc : bool
        One message object per publisher, reused every period.
    callback_groups : str
        'default' (the node's group), 'separate' (one mutually exclusive group per
        callback) or 'reentrant'.
    answer : str
        'callback': the echo answers in its subscription callback (the floor);
        'timer': on its own 1 kHz timer, the newest state (the controller's structure).
    rt_priority : int
        0: normal scheduling; 1..99: both processes under SCHED_FIFO at this priority.
    sensors : bool
        False: one state message a period (the floor). True: the topic contract's two a
        period, the load cell and then one combined joint state (wrist_pitch, jaw,
        jaw_drum), which the echo answers with the load cell it holds (the contract
        floor: the shipped nodes' message pattern, without their code).
    """

    executor: str = 'events'
    depth: int = 1
    gc_freeze: bool = True
    prealloc: bool = True
    callback_groups: str = 'default'
    answer: str = 'callback'
    rt_priority: int = 0
    sensors: bool = False

    def args(self) -> list[str]:
        out = ['--executor', self.executor, '--depth', str(self.depth),
               '--callback-groups', self.callback_groups, '--answer', self.answer]
        if self.gc_freeze:
            out.append('--gc-freeze')
        if self.prealloc:
            out.append('--prealloc')
        if self.sensors:
            out.append('--sensors')
        return out

    def label(self) -> str:
        return (f'{self.executor}, depth {self.depth}, gc.freeze {"on" if self.gc_freeze else "off"}, '
                f'prealloc {"on" if self.prealloc else "off"}, groups {self.callback_groups}, '
                f'answer on {self.answer}'
                + (f', SCHED_FIFO {self.rt_priority}' if self.rt_priority else '')
                + (', load cell + combined state (the contract)' if self.sensors else ''))


#: The settings the bench measures the floor with (the winners of the variant runs).
BEST = Variant()
#: The floor with the topic contract's two state messages a period (load cell, combined state).
CONTRACT = replace(BEST, sensors=True)

#: Variants measured by ``grip-force bench --variants``: plain rclpy defaults, the
#: EventsExecutor with one change at a time, the multi-threaded executor, the
#: chosen settings, the same answering on a timer (the controller's structure),
#: the chosen settings under SCHED_FIFO, and the contract floor.
VARIANTS = (
    Variant('single', 10, False, False),
    Variant('events', 10, False, False),
    Variant('events', 1, False, False),
    Variant('events', 10, True, False),
    Variant('events', 10, False, True),
    Variant('multi', 10, False, False, 'separate'),
    Variant('multi', 10, False, False, 'reentrant'),
    BEST,
    replace(BEST, answer='timer'),
    replace(BEST, rt_priority=50),
    CONTRACT,
)


def _window(measurer: Child, others: list[Child], seconds: float) -> dict:
    """Wait for START, meter CPU over the window, return the measurer's JSON (:func:`_windows`, one arm)."""
    return _windows({'': (measurer, others)}, seconds)['']


def run_floor(seconds: float, domain_id: int, variant: Variant = BEST, warmup: float = 1.0,
              period: float = 1e-3) -> dict:
    """Bare rclpy ping-pong at 1 kHz between two processes on loopback.

    Parameters
    ----------
    seconds : float
        Measurement window (s), after discovery and ``warmup`` (s).
    domain_id : int
        ROS_DOMAIN_ID of the two processes (nothing else may run in it).
    variant : Variant
        Executor and the other settings of both processes.
    warmup : float
        Time after discovery before the window opens (s).
    period : float
        Loop period (s).

    Returns
    -------
    dict
        ``latency`` (ms), ``periods`` (missed periods of the ping timer),
        ``cpu_percent`` per process, ``lost_fraction``, ``variant``.
    """
    env = ros_environment(domain_id)
    common = variant.args() + ['--period', str(period)]
    children = []
    try:
        rt = variant.rt_priority
        children.append(Child('echo', python_module(CHILD, 'echo', *common), env, rt_priority=rt))
        children.append(Child('ping', python_module(CHILD, 'ping', '--seconds', str(seconds),
                                                    '--warmup', str(warmup), *common), env,
                              rt_priority=rt))
        result = _window(children[1], children[:1], seconds)
    finally:
        stop_all(children)
    result['variant'] = asdict(variant)
    return result


#: ROS namespaces of the arms of a several-arm run (``grip-force bench --arms 2``): the dVRK's
#: patient-side manipulators, two or three per console (the command lines offer two: three
#: arms have not been run).
ARM_NAMESPACES = ('PSM1', 'PSM2', 'PSM3')
#: Time (s) from the start of a several-arm run's processes to the one window all its sims
#: open together (discovery of every node and the warm-up fit in it on a quiet machine; a sim
#: that is not warm by then opens its window late, ``window_skew_s``).
ARMS_WINDOW_DELAY = 15.0


def arm_ros_args(namespace: str = '', *args, **kwargs) -> list[str]:
    """:func:`~grip_force_ros.lab.processes.ros_args` with ``-r __ns:=/<namespace>`` when given.

    The crtk topic names are relative, so the arm's topics go under its namespace
    (``/PSM1/instrument/measured_js``); /diagnostics stays absolute.
    """
    if namespace:
        kwargs['remaps'] = {'__ns': '/' + namespace.strip('/'), **(kwargs.get('remaps') or {})}
    return ros_args(*args, **kwargs)


def product_commands(config: str, answers: str, steps: str, seconds: float, warmup: float,
                     namespace: str = '', controller_params: dict | None = None,
                     open_at_ns: int = 0, load_cell: bool = False) -> dict[str, list[str]]:
    """Return the command lines of one arm's product: controller, master, sim (in start order).

    Parameters
    ----------
    config : str
        Instrument YAML of the three nodes.
    answers, steps : str
        The sim's and the controller's record files (.npz).
    seconds, warmup : float
        The sim's measurement window and warm-up (s).
    namespace : str
        ROS namespace of the arm ('' : the root, the single-arm run).
    controller_params : dict, optional
        Further controller parameters over the file's.
    open_at_ns : int
        Wall clock (ns) before which the sim's window does not open (0: after its warm-up).
    load_cell : bool
        The controller's ``force_sensor_enabled``: False, sensorless (the shipped default,
        one state message a period); True, the load cell closes the force loop (two).
    """
    sim_extra = ['--open-at-ns', str(int(open_at_ns))] if open_at_ns else []
    return {
        'controller': python_module(
            'grip_force_ros.lab.bench.product_controller', '--record', steps,
            *arm_ros_args(namespace, config, {'force_sensor_enabled': load_cell,
                                              **(controller_params or {})},
                          log_level='warn')),
        'master': node_executable('master') + arm_ros_args(
            namespace, config, {'repeat': True}, log_level='warn'),
        'sim': python_module(
            'grip_force_ros.lab.bench.product_sim', '--seconds', str(seconds), '--warmup', str(warmup),
            '--record', answers, *sim_extra, *arm_ros_args(namespace, config, log_level='warn')),
    }


def _label(arm: str, child: Child) -> str:
    return f'{arm} {child.name}' if arm else child.name


def _windows(arms: dict[str, tuple[Child, list[Child]]], seconds: float) -> dict[str, dict]:
    """:func:`_window` of several arms at once: each sim's START, then each one's JSON."""
    out: dict[str, dict] = {}
    for arm, (measurer, others) in arms.items():
        line = measurer.wait_line(lambda line: line == 'START' or line.startswith('{'), START_TIMEOUT)
        if line != 'START':
            raise BenchError(f'{_label(arm, measurer)}: {json.loads(line).get("error", line)}')
        for c in [measurer] + others:
            c.cpu_start()
    for arm, (measurer, others) in arms.items():
        line = measurer.wait_line(lambda line: line.startswith('{'), seconds + 30.0)
        for c in [measurer] + others:
            c.cpu_stop()
        result = json.loads(line)
        if 'error' in result:
            raise BenchError(f'{_label(arm, measurer)}: {result["error"]}')
        result['cpu_percent'] = {c.name: c.cpu_percent for c in [measurer] + others}
        out[arm] = result
    return out


def run_products(seconds: float, domain_id: int, config: str | None = None, warmup: float = 2.0,
                 rt_priority: int = 0, controller_params: dict | None = None,
                 namespaces: tuple[str, ...] = ('',),
                 window_delay: float = ARMS_WINDOW_DELAY, load_cell: bool = False) -> dict[str, dict]:
    """Measure one product per arm, all at once in one ROS domain, each in its own namespace.

    Each arm is what :func:`run_product` starts (controller, master, sim), its nodes in
    the namespace ``/<arm>``. With more than one arm every sim opens its window at one wall
    clock time (:data:`ARMS_WINDOW_DELAY` after the start), so the arms are measured in one
    window, and ``window_skew_s`` of each says how far its window opened from the first's.

    Parameters
    ----------
    seconds, domain_id, config, warmup, rt_priority, controller_params, load_cell
        As :func:`run_product`.
    namespaces : tuple of str
        ROS namespaces of the arms ('' : the root namespace, one arm).
    window_delay : float
        With several arms: time (s) from the start to the window they share.

    Returns
    -------
    dict
        Arm namespace -> the :func:`run_product` result of that arm.
    """
    env = ros_environment(domain_id)
    config = str(instrument_path(config).resolve())
    open_at_ns = time.time_ns() + int(window_delay * 1e9) if len(namespaces) > 1 else 0
    children: list[Child] = []
    arms: dict[str, tuple[Child, list[Child]]] = {}
    files: dict[str, tuple[str, str]] = {}
    with tempfile.TemporaryDirectory(prefix='gf_bench_') as tmp:
        try:
            for arm in namespaces:
                tag = arm or 'arm'
                files[arm] = f'{tmp}/{tag}_answers.npz', f'{tmp}/{tag}_steps.npz'
                cmds = product_commands(config, *files[arm], seconds, warmup, arm,
                                        controller_params, open_at_ns, load_cell)
                controller = Child('controller', cmds['controller'], env, rt_priority=rt_priority)
                master = Child('master', cmds['master'], env)
                sim = Child('sim', cmds['sim'], env, rt_priority=rt_priority)
                children += [controller, master, sim]
                arms[arm] = sim, [controller, master]
            results = _windows(arms, seconds)
            for arm, (_sim, others) in arms.items():
                for c in others:
                    if not c.alive():
                        raise BenchError(f'{_label(arm, c)} died during the run; '
                                         'last output:\n' + '\n'.join(c.tail))
        finally:
            stop_all(children)
        for arm, result in results.items():
            answers, steps = files[arm]
            try:
                with np.load(answers) as a, np.load(steps) as s:
                    result['full_path'] = full_path(a['answered_ns'], a['round_trip_ns'], dict(s),
                                                    result['period_s'])
            except OSError as exc:
                raise BenchError(f'full path{" of " + arm if arm else ""}: a record is missing '
                                 f'({exc}); controller output:\n'
                                 + '\n'.join(arms[arm][1][0].tail)) from None
    opened = [r.get('opened_ns', 0) for r in results.values()]
    for arm, result in results.items():
        result['config'] = config
        result['rt_priority'] = rt_priority
        result['load_cell'] = load_cell
        if len(namespaces) > 1:
            result['namespace'] = '/' + arm
            result['window_skew_s'] = (result.get('opened_ns', 0) - min(opened)) * 1e-9
    return results


def run_product(seconds: float, domain_id: int, config: str | None = None, warmup: float = 2.0,
                rt_priority: int = 0, controller_params: dict | None = None,
                load_cell: bool = False) -> dict:
    """Measure the sim -> controller -> sim round trip and the full path at 1 kHz, the shipped nodes.

    Starts the shipped controller node as :mod:`.product_controller` (it notes the input
    stamps of each step), sensorless or with the load cell in the loop, a ``master``
    repeating the needle grasp (the shipped executable), all with ``--params-file config``,
    and the shipped sim node as :mod:`.product_sim`, which keeps its loop's round trips for
    the window.

    Parameters
    ----------
    seconds : float
        Measurement window (s).
    domain_id : int
        ROS_DOMAIN_ID of the run.
    config : str, optional
        Instrument YAML (path or shipped name) for the sim, the controller and the
        master; default :data:`~grip_force_ros.params.files.DEFAULT_INSTRUMENT`.
    warmup : float
        Time after discovery before the window opens (s).
    rt_priority : int
        0: normal scheduling; 1..99: sim and controller under SCHED_FIFO at this
        priority (the master stays normal).
    controller_params : dict, optional
        Further controller parameters (name -> value) over the instrument file's, e.g.
        ``{'control_rate': 250.0}``.
    load_cell : bool
        False: sensorless, the shipped default (one state message a period). True:
        ``force_sensor_enabled``, the load cell is one of the inputs whose path is measured.

    Returns
    -------
    dict
        ``latency`` (ms, stamp of the state the controller steps on -> command arrival at
        the sim), ``full_path`` (ms, per input and the oldest), ``periods`` (sim periods
        with no answer), ``timer_periods`` (the sim's timer), ``cpu_percent`` per process,
        ``other_commands`` (commands that answer no fresh state: the controller's timer
        fallback), ``worst``.
    """
    return run_products(seconds, domain_id, config, warmup, rt_priority, controller_params,
                        namespaces=('',), load_cell=load_cell)['']


#: The loop's goals: product p99 and full-path p99 at most this many times the reference
#: floor's p99, missed periods at most its plus :data:`MISSED_OVER_FLOOR`, the controller's
#: CPU at most :data:`CPU_RATIO_GOAL` times its echo's. The reference floor carries the
#: product's messages: the floor (sensorless), the contract floor (load cell).
P99_RATIO_GOAL = 1.5
MISSED_OVER_FLOOR = 0.0005
CPU_RATIO_GOAL = 1.5


def compare(floor: dict, product: dict, contract_floor: dict | None = None) -> dict:
    """Build the ``loop`` section: product/floor ratios beside both runs' figures, the goals judged.

    The goals are judged against the floor that carries the product's messages
    (``reference``): the floor for a sensorless product (one state message a period), the
    contract floor for one with the load cell (``product['load_cell']``: the load cell and
    the combined state). ``contract_floor`` (a :func:`run_floor` result with
    ``Variant.sensors``), when given, also splits the full path's excess over the floor
    in two: ``contract_floor_p99_ratio`` (contract floor p99 / floor p99: the topic
    contract's second message a period, bare rclpy) and ``full_path_over_contract_p99_ratio``
    (full-path p99 / contract floor p99: this package's code: message checks, model,
    control law, force outputs).

    Parameters
    ----------
    floor, contract_floor : dict
        :func:`run_floor` results (the floor; the contract floor, needed for a load-cell product).
    product : dict
        A :func:`run_product` result (or one arm's of :func:`run_products`).

    Returns
    -------
    dict
        Ratios (-), latencies (ms), fractions (-), CPU (% of one core), ``reference``
        ('floor' or 'contract_floor'), ``goals`` and ``goals_met`` (judged in this run;
        NaN is not met).
    """
    load_cell = bool(product.get('load_cell', False))
    if load_cell and contract_floor is None:
        raise ValueError('a load-cell product is judged against the contract floor: none given')
    ref = contract_floor if load_cell else floor
    fl, rl, pl = floor['latency'], ref['latency'], product['latency']
    fp = product['full_path']
    missed, ref_missed = product['periods']['missed_fraction'], ref['periods']['missed_fraction']
    p99_ratio = ratio(pl['p99_ms'], rl['p99_ms'])
    full_path_ratio = ratio(fp['full_path']['p99_ms'], rl['p99_ms'])
    # the controller's CPU (% of a core) over the reference echo's: what the node costs beyond rclpy
    cpu_ratio = ratio(product['cpu_percent'].get('controller', math.nan),
                      ref['cpu_percent'].get('echo', math.nan))
    split = {}
    if contract_floor is not None:
        cl = contract_floor['latency']
        split = {
            'contract_floor_p99_ratio': ratio(cl['p99_ms'], fl['p99_ms']),
            'contract_floor_p50_ratio': ratio(cl['p50_ms'], fl['p50_ms']),
            'full_path_over_contract_p99_ratio': ratio(fp['full_path']['p99_ms'], cl['p99_ms']),
            'full_path_over_contract_p50_ratio': ratio(fp['full_path']['p50_ms'], cl['p50_ms']),
            'contract_floor_missed_fraction': contract_floor['periods']['missed_fraction'],
            # answers of the contract floor's echo that used the load cell of their own
            # period (the product's figure: full_path.inputs.*.same_sample_fraction)
            'contract_floor_same_sample_fraction': contract_floor.get('sensors_same_sample_fraction'),
            'contract_floor': {k: cl[k] for k in ('p50_ms', 'p99_ms', 'max_ms', 'samples')},
        }
    return {
        'load_cell': load_cell,
        'reference': 'contract_floor' if load_cell else 'floor',
        'p99_ratio': p99_ratio,
        'p50_ratio': ratio(pl['p50_ms'], rl['p50_ms']),
        'max_ratio': ratio(pl['max_ms'], rl['max_ms']),
        # sensing to actuation: the oldest input of each step (actuator state, jaw angle,
        # load cell when used) to its command's arrival, p99 / the reference's round-trip p99
        'full_path_p99_ratio': full_path_ratio,
        'controller_cpu_ratio': cpu_ratio,
        'missed_fraction': missed,
        'floor_missed_fraction': floor['periods']['missed_fraction'],
        'reference_missed_fraction': ref_missed,
        # gaps of the state publisher's own 1 kHz timer (part of the missed periods)
        'timer_missed_fraction': product['timer_periods']['missed_fraction'],
        'floor_timer_missed_fraction': floor['timer_periods']['missed_fraction'],
        # gaps between answered states longer than 1.5 periods (missed or late)
        'late_fraction': product['periods']['late_fraction'],
        'floor_late_fraction': floor['periods']['late_fraction'],
        'floor': {k: fl[k] for k in ('p50_ms', 'p99_ms', 'max_ms', 'samples')},
        'product': {k: pl[k] for k in ('p50_ms', 'p99_ms', 'max_ms', 'samples')},
        'full_path': {**{k: fp['full_path'][k] for k in ('p50_ms', 'p99_ms', 'max_ms', 'samples')},
                      'matched_fraction': fp['matched_fraction'], 'inputs': fp['inputs']},
        **split,
        'cpu_percent': {'floor': floor['cpu_percent'], 'product': product['cpu_percent'],
                        **({'contract_floor': contract_floor['cpu_percent']} if contract_floor else {})},
        # the product's longest round trips: (s into the window, ms)
        'product_worst': product.get('worst', []),
        'goals': {'p99_ratio': P99_RATIO_GOAL, 'full_path_p99_ratio': P99_RATIO_GOAL,
                  'missed_fraction': ref_missed + MISSED_OVER_FLOOR,
                  'controller_cpu_ratio': CPU_RATIO_GOAL},
        # judged in this run (NaN -> not met)
        'goals_met': {'p99_ratio': _at_most(p99_ratio, P99_RATIO_GOAL),
                      'full_path_p99_ratio': _at_most(full_path_ratio, P99_RATIO_GOAL),
                      'missed_fraction': _at_most(missed, ref_missed + MISSED_OVER_FLOOR),
                      'controller_cpu_ratio': _at_most(cpu_ratio, CPU_RATIO_GOAL)},
    }


def _at_most(value: float, goal: float) -> bool:
    return bool(value == value and goal == goal and value <= goal)


def compare_arms(floor: dict, products: dict[str, dict], contract_floor: dict | None = None) -> dict:
    """Build the ``loop`` section of a several-arm run: each arm judged against the one floor.

    Parameters
    ----------
    floor, contract_floor : dict
        The run's :func:`run_floor` results (measured once, before the arms).
    products : dict
        Arm namespace -> that arm's :func:`run_products` result.

    Returns
    -------
    dict
        ``arms``: arm -> the :func:`compare` section of that arm (the single-arm loop
        section's keys, plus ``window_skew_s``: s between the opening of its window and
        the first arm's); ``arms_goals_met``: every arm met every goal; the floor's and the
        contract floor's figures once (ms, fractions, ``cpu_percent`` in % of one core).
    """
    arms = {}
    for arm, product in products.items():
        arms[arm] = compare(floor, product, contract_floor)
        arms[arm]['window_skew_s'] = product.get('window_skew_s', 0.0)
        arms[arm]['product_fallback_commands'] = product.get('other_commands')
    fl = floor['latency']
    out = {
        'arms': arms,
        'arms_goals_met': bool(arms) and all(all(a['goals_met'].values()) for a in arms.values()),
        'floor': {k: fl[k] for k in ('p50_ms', 'p99_ms', 'max_ms', 'samples')},
        'floor_missed_fraction': floor['periods']['missed_fraction'],
        'floor_timer_missed_fraction': floor['timer_periods']['missed_fraction'],
        'cpu_percent': {'floor': floor['cpu_percent'],
                        **({'contract_floor': contract_floor['cpu_percent']} if contract_floor else {}),
                        'arms': {arm: p['cpu_percent'] for arm, p in products.items()}},
    }
    if contract_floor is not None:
        cl = contract_floor['latency']
        out['contract_floor'] = {k: cl[k] for k in ('p50_ms', 'p99_ms', 'max_ms', 'samples')}
        out['contract_floor_missed_fraction'] = contract_floor['periods']['missed_fraction']
    return out
