"""One bench run: the loop (floor and product), the model, the diagnosis, and the machine."""
from __future__ import annotations

import os
import platform
from dataclasses import replace
import sys
import time
from importlib import metadata

from grip_force_ros.lab.bench.loop import (ARM_NAMESPACES, BEST, VARIANTS, Variant, compare,
                                           compare_arms, run_floor, run_product, run_products)
from grip_force_ros.lab.bench.procs import DomainLock
from grip_force_ros.params.files import config_dir, instrument_path

PARTS = ('loop', 'model', 'diagnosis')


def machine() -> dict:
    """Describe what the figures were measured on."""
    model = platform.processor() or ''
    try:
        with open('/proc/cpuinfo') as fh:
            for line in fh:
                if line.startswith('model name'):
                    model = line.split(':', 1)[1].strip()
                    break
    except OSError:
        pass
    versions = {}
    for dist in ('ros-jazzy-rclpy', 'numpy'):
        try:
            versions[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            versions[dist] = None
    return {'nproc': os.cpu_count(), 'cpu_model': model, 'python': platform.python_version(),
            'rclpy': versions['ros-jazzy-rclpy'], 'numpy': versions['numpy'],
            'rmw': os.environ.get('RMW_IMPLEMENTATION', 'default (rmw_fastrtps_cpp)'),
            'load_average_1min': os.getloadavg()[0]}


def parse_domains(text: str | None) -> list[int] | None:
    """'70-99' or '70,71' -> list of domain ids; None -> the default choice."""
    if not text:
        return None
    out: list[int] = []
    for part in text.split(','):
        if '-' in part:
            lo, hi = part.split('-')
            out.extend(range(int(lo), int(hi) + 1))
        else:
            out.append(int(part))
    return out


#: Time the loop part may take beyond its three measurement windows (s): the processes'
#: start and stop; the bound of the pressure generator's deadline.
LOOP_OVERHEAD = 300.0


def run_loop(seconds: float, domains=None, config: str | None = None, variant: Variant = BEST,
             rt_priority: int = 0, say=None,
             pressure: str = 'none', pressure_options: dict | None = None, arms: int = 1,
             load_cell: bool = False) -> dict:
    """Measure the ``loop`` section in one free domain: floor, contract floor, product, their ratios.

    Parameters
    ----------
    seconds : float
        Measurement window of each of the three runs (s).
    domains, config, variant, rt_priority, say
        As :func:`run_bench`.
    pressure : str
        Load during the three runs, the same for floor and product:
        'none' (default), 'cpu' (:class:`~grip_force_ros.lab.bench.load.LoadGenerator`, one busy
        process per core), 'disk' (:class:`~grip_force_ros.lab.bench.pressure.DiskPressure`:
        fsync writers, page-cache eviction of the package's files) or 'both'; its summary
        is ``pressure`` in the result.
    pressure_options : dict, optional
        Keywords of :func:`~grip_force_ros.lab.bench.pressure.make_pressure` (the disk
        pressure's sizes and rates, the CPU load's workers and duty).
    arms : int
        1: one product in the root namespace (the section's keys as ever). 2 or 3: that many
        products at once (:data:`~grip_force_ros.lab.bench.loop.ARM_NAMESPACES`: /PSM1, /PSM2,
        ...), one domain, one window, each judged against the run's one floor
        (:func:`~grip_force_ros.lab.bench.loop.compare_arms`: ``arms``, ``arms_goals_met``).
    load_cell : bool
        False (default): the controller sensorless, as shipped, judged against the floor.
        True: its force loop on the load cell, judged against the contract floor.
    """
    if not 1 <= arms <= len(ARM_NAMESPACES):
        raise ValueError(f'arms must be 1..{len(ARM_NAMESPACES)}, got {arms}')
    from grip_force_ros.lab.bench.load import MAX_SECONDS
    from grip_force_ros.lab.bench.pressure import describe, make_pressure

    say = say or (lambda msg: None)
    variant = replace(variant, rt_priority=rt_priority)
    contract = replace(variant, sensors=True)
    load = make_pressure(pressure, seconds=min(3 * seconds + LOOP_OVERHEAD, MAX_SECONDS),
                         **(pressure_options or {}))
    with DomainLock(domains) as domain:
        if pressure != 'none':
            say(f'loop: under pressure, {describe(load)}')
        with load:
            say(f'loop: floor ping-pong, {seconds:g} s, ROS_DOMAIN_ID {domain} ({variant.label()})')
            floor = run_floor(seconds, domain, variant)
            say(f'loop: contract floor, {seconds:g} s ({contract.label()})')
            contract_floor = run_floor(seconds, domain, contract)
            if arms == 1:
                say(f'loop: product sim -> controller -> sim, {seconds:g} s, {config}, '
                    f"{'load cell' if load_cell else 'sensorless'}")
                product = run_product(seconds, domain, config, rt_priority=rt_priority,
                                      load_cell=load_cell)
            else:
                names = ARM_NAMESPACES[:arms]
                say(f'loop: {arms} products at once ({", ".join("/" + n for n in names)}), '
                    f'sim -> controller -> sim each, {seconds:g} s, {config}')
                products = run_products(seconds, domain, config, rt_priority=rt_priority,
                                        namespaces=names,
                                        load_cell=load_cell)
    if arms == 1:
        out = compare(floor, product, contract_floor)
        out['product_fallback_commands'] = product['other_commands']
    else:
        out = compare_arms(floor, products, contract_floor)
    out.update({'seconds': seconds, 'domain_id': domain, 'floor_variant': floor['variant'],
                'floor_lost_fraction': floor['lost_fraction'],
                'rt_priority': rt_priority,
                'pressure': load.last_summary})
    return out


def run_variants(seconds: float, domains=None, variants=VARIANTS, say=None) -> list[dict]:
    """Measure the floor with each variant in turn (same domain, one after the other)."""
    say = say or (lambda msg: None)
    rows = []
    with DomainLock(domains) as domain:
        for variant in variants:
            say(f'variant: {variant.label()}')
            r = run_floor(seconds, domain, variant)
            rows.append({'variant': r['variant'], 'label': variant.label(),
                         **{k: r['latency'][k] for k in ('p50_ms', 'p99_ms', 'max_ms')},
                         'missed_fraction': r['periods']['missed_fraction'],
                         'lost_fraction': r['lost_fraction'], 'cpu_percent': r['cpu_percent'],
                         'load_average_1min': os.getloadavg()[0]})
    return rows


def run_bench(seconds: float = 20.0, parts=PARTS, *, domains=None, config: str | None = None,
              log_minutes: float = 60.0, model_size: int = 100_000, variants: bool = False,
              variant_seconds: float | None = None,
              rt_priority: int = 0, pressure: str = 'none', pressure_options: dict | None = None,
              arms: int = 1, load_cell: bool = False, say=None) -> dict:
    """Everything ``grip-force bench`` measures, as the nested JSON dict.

    Parameters
    ----------
    seconds : float
        Measurement window of each loop run (s).
    parts : iterable of str
        Any of :data:`PARTS`.
    domains : list of int, optional
        Candidate ROS domains (default: ROS_DOMAIN_ID if set, else 200..232).
    config : str, optional
        Instrument YAML (path or shipped name) of the product run and the model figures;
        default :data:`~grip_force_ros.params.files.DEFAULT_INSTRUMENT`.
    log_minutes : float
        Length of the diagnosis log at 1 kHz (min).
    model_size : int
        Samples per array of the vectorised model figures.
    variants : bool
        Also measure the floor with every variant of :data:`VARIANTS`.
    variant_seconds : float, optional
        Window of each variant run (s); default ``seconds``.
    rt_priority : int
        0, or SCHED_FIFO priority of the 1 kHz processes of the floor and the product alike.
    pressure : str
        'none', 'cpu', 'disk' or 'both': the load under which the loop part's floor and
        product run (:func:`run_loop`; the model and diagnosis parts run without it).
    pressure_options : dict, optional
        Keywords of :func:`~grip_force_ros.lab.bench.pressure.make_pressure`.
    arms : int
        Products measured at once in the loop part (1, or 2-3 arms /PSM1, /PSM2, ...;
        :func:`run_loop`).
    load_cell : bool
        The product's controller on the load cell, judged against the contract floor
        (:func:`run_loop`; default sensorless, against the floor).
    say : callable, optional
        ``say(message)`` before each step.

    Returns
    -------
    dict
        ``{"loop": {"p99_ratio", "missed_fraction", ...}, "model": {"forward_ratio",
        "step_share", ...}, "diagnosis": {"load_ratio", ...}, "machine": {...}}``
        (only the parts asked for).
    """
    say = say or (lambda msg: None)
    config = str(instrument_path(config))
    out: dict = {'machine': machine()}
    started = time.perf_counter()
    if 'model' in parts:
        from grip_force_ros.lab.bench.model_speed import run_model
        say('model: vectorised forward/inverse vs numpy.exp, control step')
        nonlinear = config_dir() / 'four_pulley_needle_driver.yaml'
        out['model'] = run_model(config, size=model_size,
                                 other_configs=(str(nonlinear),) if nonlinear.is_file() else ())
    if 'loop' in parts:
        out['loop'] = run_loop(seconds, domains, config, rt_priority=rt_priority, say=say, pressure=pressure,
                               pressure_options=pressure_options, arms=arms,
                               load_cell=load_cell)
    if variants:
        out['variants'] = run_variants(variant_seconds or seconds, domains, say=say)
    if 'diagnosis' in parts:
        from grip_force_ros.lab.bench.diagnosis_speed import run_diagnosis_speed
        say(f'diagnosis: {log_minutes:g} min log at 1 kHz (built once, cached)')
        out['diagnosis'] = run_diagnosis_speed(log_minutes)
    out['machine']['load_average_1min_end'] = os.getloadavg()[0]
    out['machine']['bench_seconds'] = time.perf_counter() - started
    out['machine']['argv'] = sys.argv
    return out
