"""``grip-force demo --compare-instruments``: one master trajectory, three instruments.

Not rigged: each simulated plant runs with its cable-pulley friction
coefficient and cable stiffness ``plant_error`` (20 %) off what its YAML says,
in alternating directions (``friction_scale``/``stiffness_scale`` of the sim;
the controller is not told). As a lab would, every instrument first does a
calibration grasp on the load cell (a few force levels); ``calibrate`` fits
its friction coefficient and writes a calibrated YAML. Then, all through the
real ROS processes, per instrument:

``controlled``    calibrated YAML, no force sensor (model estimate feedback)
``uncalibrated``  YAML as shipped, no force sensor
``sensor``        YAML as shipped, load-cell feedback (force_sensor_enabled)
``naive``         current proportional to the master closing, ONE gain for all

For each, the steady hold force / target; the spread of a condition is max - min
over the instruments.
"""
from __future__ import annotations

import concurrent.futures as cf
import json
import multiprocessing
import time
from pathlib import Path
from typing import Any, Sequence, TextIO

import numpy as np

from grip_force_ros.lab.demo import comparison_configs
from grip_force_ros.lab.demo.analysis import spread
from grip_force_ros.identify.procedures import (CALIBRATION_FIRST_RAMP, CALIBRATION_HOLD,
                                                CALIBRATION_RAMP, CALIBRATION_SHARES,
                                                calibration_current)

CONDITIONS = ('controlled', 'uncalibrated', 'sensor', 'naive')
#: Master trajectory length of the comparison runs (s): the needle grasp at time_scale 1.2.
TASK_DURATION = 6.0


def plant_scales(index: int, plant_error: float) -> dict[str, float]:
    """Sim friction/stiffness scales of instrument ``index``: signs alternate per instrument.

    The first instrument gets the lower friction (and stiffer cable), the second the
    higher, and so on. With the shipped configs sorted by name, the lossiest one (the
    four-pulley driver: 2.76 N at 0.5 A with +20 % friction) comes first, so every
    plant can still reach the 4 N target.
    """
    sign = -1.0 if index % 2 == 0 else 1.0
    return {'friction_scale': round(1.0 + sign * plant_error, 6),
            'stiffness_scale': round(1.0 - sign * plant_error, 6)}


def calibration_csv(params, path: Path) -> Path:
    """Write the calibration grasp (t, master_angle) for an instrument's force map.

    Open, close to the first level past contact, then a staircase up through
    :data:`~grip_force_ros.identify.procedures.CALIBRATION_SHARES` of the travel from the
    contact angle to fully closed (slow ramps: the pulley friction is then in its loading
    direction, as the model describes it), then open again. Through the naive map (current
    proportional to the master closing) this is the current staircase the controller's
    ``~/calibrate`` runs (:class:`~grip_force_ros.identify.procedures.CurrentStaircase`).
    """
    open_angle = min(0.8, params.master_angle_max)
    contact, closed = params.master_contact_angle, params.master_angle_min
    rows = [(0.0, open_angle), (0.4, open_angle)]
    t = 0.4
    for k, share in enumerate(CALIBRATION_SHARES):
        t += CALIBRATION_FIRST_RAMP if k == 0 else CALIBRATION_RAMP
        angle = contact - share * (contact - closed)
        rows.append((t, angle))
        t += CALIBRATION_HOLD
        rows.append((t, angle))
    t += CALIBRATION_RAMP
    rows.append((t, open_angle))
    rows.append((t + 0.2, open_angle))
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text('t,master_angle\n' + ''.join(f'{a:.4f},{b:.6f}\n' for a, b in rows))
    return path


def naive_gain(reference_config: Path) -> float:
    """Return the naive map's one gain (A).

    The current that gives grip_force_max on the reference instrument per its shipped
    model, on the needle (the gain a lab would tune on one tool).
    """
    from grip_force_ros.model import GripForceModel
    from grip_force_ros.params import load_params_file
    p = load_params_file(reference_config)
    jaw = 0.0  # closed on a 0.5 mm needle: the needle contact gain does not depend on it
    return float(GripForceModel(p).inverse(p.grip_force_max, 0.0, jaw, 'needle'))


#: Attempts per run: a run whose hold phase a starved node spoiled is done again.
ATTEMPTS = 3


def _run_worker(job: dict[str, Any]) -> dict[str, Any]:
    """One run (again if the machine spoiled it or it could not be completed); a JSON-able summary.

    A run that raises :class:`~grip_force_ros.lab.processes.ProcessError` (a node that
    died or never came up, a master that answered none of the requests to start its task,
    each after its own bounded retry) counts as a spoiled attempt and is done again. When
    no attempt completed, the summary says so (``completed`` false, ``problems``: why)
    instead of raising: the comparison goes on with the other runs.
    """
    from grip_force_ros.lab.demo.run import RunSpec, run_task
    from grip_force_ros.lab.processes import ProcessError
    spec = RunSpec(**job['spec'])
    t0 = time.monotonic()
    spoiled = []
    result = error = None
    for attempt in range(1, ATTEMPTS + 1):
        out_dir = Path(job['out_dir'] if attempt == 1 else f"{job['out_dir']}_retry{attempt - 1}")
        try:
            done = run_task(spec, out_dir, job['domain_id'], analyse=job['analyse'],
                            plot=job['plot'])
        except ProcessError as exc:
            error = str(exc)
            spoiled.append({'out_dir': str(out_dir), 'problems': [f'not completed: {error}']})
            continue
        result = done
        problems = result.problems or (calibration_problems(result) if job.get('calibration')
                                       else [])
        if not problems:
            break
        result.problems = problems
        spoiled.append({'out_dir': str(out_dir), 'problems': problems})
    if result is None:
        out = not_completed(job, f'not completed in {ATTEMPTS} attempts: {error}')
    else:
        out = result.as_dict()
        out['completed'] = True
    out['spoiled_attempts'] = spoiled
    out['wall_time'] = time.monotonic() - t0
    return out


def not_completed(job: dict[str, Any], reason: str) -> dict[str, Any]:
    """Return the summary of a run that could not be completed, saying why (``problems``)."""
    spec = job['spec']
    return {'label': spec.get('label', ''), 'config': str(spec.get('config')),
            'controller': spec.get('controller', 'controller'), 'completed': False,
            'out_dir': job['out_dir'], 'bag': None, 'plot': None, 'metrics': None,
            'safe_state_entries': [], 'late_inputs': {}, 'scheduling': {},
            'problems': [reason], 'spoiled_attempts': [], 'wall_time': 0.0}


def calibration_problems(result) -> list[str]:
    """Why a calibration run cannot be fitted (empty if it can): a live drive cut.

    A calibration run is not analysed as a task (no force loop, no hold phase);
    what spoils it is the drive cutting a held current (a starved node), read from
    the sim's /diagnostics in the run's bag up to the master's last sample.
    """
    from grip_force_ros.lab.demo import analysis
    from grip_force_ros.lab.demo.series import read_bag_series

    recorded = result.spec.recorded()
    series, diagnostics = read_bag_series(result.bag, recorded)
    master = series[recorded.names.master_js]['t']
    until = float(master[-1]) if len(master) else float('inf')
    cuts = analysis.drive_cuts_under_current(diagnostics, until)
    if cuts:
        return [f'the drive cut a held current {cuts} time(s) during the calibration staircase '
                '(no command for 30 ms: a starved node)']
    return []


def _run_all(jobs: list[dict], parallel: bool, log: TextIO | None) -> list[dict]:
    if not parallel:
        results = []
        for job in jobs:
            results.append(_run_worker(job))
            _log(log, _done(job, results[-1]))
        return results
    ctx = multiprocessing.get_context('spawn')
    with cf.ProcessPoolExecutor(max_workers=len(jobs), mp_context=ctx) as pool:
        futures = [pool.submit(_run_worker, job) for job in jobs]
        results = []
        for job, fut in zip(jobs, futures):
            results.append(fut.result())
            _log(log, _done(job, results[-1]))
        return results


def _done(job: dict, result: dict) -> str:
    ratio = (result.get('metrics') or {}).get('steady_ratio')
    if not result.get('completed', True):
        return f"  {job['spec']['label']}: NOT COMPLETED ({result['problems'][0]})"
    text = f"  {job['spec']['label']}: done ({result['wall_time']:.1f} s"
    if ratio is not None:
        text += f', steady hold force / target {ratio:.3f}'
    late = (result.get('late_inputs') or {}).get('total')
    if late:
        text += f', {late} late input(s)'
    if result['spoiled_attempts']:
        text += f", {len(result['spoiled_attempts'])} spoiled run(s) redone: " \
                f"{result['spoiled_attempts'][0]['problems'][0]}"
    if result.get('problems'):
        text += f"; STILL SPOILED: {result['problems'][0]}"
    return text + ')'


def _log(stream: TextIO | None, text: str) -> None:
    if stream is not None:
        stream.write(text + '\n')
        stream.flush()


def compare_instruments(out_dir: str | Path, configs: Sequence[Path] | None = None,
                        plant_error: float = 0.2, parallel: bool = False,
                        domain_id: int | None = None, task_duration: float = TASK_DURATION,
                        log: TextIO | None = None, conditions: Sequence[str] = CONDITIONS,
                        plot: bool = True, rt_priority: int | None = None,
                        plants: Sequence[Path] | None = None) -> dict[str, Any]:
    """Calibrate, then run the four conditions on every instrument; return the report.

    Parameters
    ----------
    out_dir : path
        Everything goes here: calibration bags and YAMLs, one directory per run.
    configs : sequence of Path, optional
        Instrument YAMLs the controllers are given (default :func:`comparison_configs`; with
        ``plants``, the plants' own files).
    plant_error : float
        Relative friction / stiffness error of each simulated plant (not with ``plants``).
    plants : sequence of Path, optional
        Instrument YAMLs the simulated plants run, in place of the perturbed ``configs``
        (e.g. twins of rig folders, ``grip-force twin``): plant k with controller file k.
    parallel : bool
        Run the instruments of a stage at the same time (one process and
        ROS domain each). Needs spare cores: each run is three 1 kHz nodes.
    domain_id : int, optional
        First ROS domain id to use (default: free ones).
    task_duration : float
        Length of each run's needle-grasp task (s).
    log : text stream, optional
        Progress lines go here (default: none).
    conditions : sequence of str
        Which of :data:`CONDITIONS` to run after the calibration (default all; the CI test
        of the calibrated sensorless spread runs 'controlled' only).
    plot : bool
        Draw ``compare.png`` (needs every condition).
    rt_priority : int, optional
        SCHED_FIFO priority of every run's sim and controller (default: :class:`RunSpec`'s;
        0: normal scheduling).

    Returns
    -------
    dict
        ``instruments`` (per-instrument details) and ``spread_controlled``,
        ``spread_uncalibrated``, ``spread_sensor``, ``spread_naive``; the same over the
        runs no starved node spoiled (``spread_<condition>_unspoiled``, None when fewer
        than two), ``runs_still_spoiled`` and ``runs_not_completed`` (a run no attempt
        completed, or not run for want of its calibration: which instrument and run, why;
        its ratio is None and the spreads leave it out as they do a missing one).
    """
    from grip_force_ros.identify import calibrated_yaml, fit_instrument
    from grip_force_ros.lab.processes import reserve_domains
    from grip_force_ros.logs import read_log
    from grip_force_ros.params import load_params_file

    unknown = [c for c in conditions if c not in CONDITIONS]
    if unknown or not conditions:
        raise ValueError(f'conditions {list(conditions)}: each one of {CONDITIONS}')
    conditions = [c for c in CONDITIONS if c in conditions]
    started = time.monotonic()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    plants = [Path(c) for c in plants] if plants else None
    configs = [Path(c) for c in (configs or plants or comparison_configs())]
    if plants is not None and len(plants) != len(configs):
        raise ValueError(f'--plants gives {len(plants)} files, --configs {len(configs)}: one '
                         'controller file per plant')
    if len(configs) < 2:
        raise ValueError('--compare-instruments needs at least two instrument YAMLs')
    sims = plants or configs
    names = [load_params_file(c).instrument_name for c in sims]
    if len(set(names)) < len(names):        # two plants of one instrument name: their files'
        names = [f'{k}_{name}' for k, name in enumerate(names)]
    n = len(configs)
    if domain_id is not None:
        domains = list(range(domain_id, domain_id + n))
    else:   # free domains, held until this function returns (no other run takes them)
        held = reserve_domains(n)
        domains = held.ids
    scales = [{} if plants else plant_scales(k, plant_error) for k in range(n)]
    scheduling = {} if rt_priority is None else {'rt_priority': rt_priority}
    gain = naive_gain(configs[0])
    plant_text = ('plants ' + ', '.join(p.name for p in plants) if plants else
                  f'plants off by {plant_error:.0%} (friction, stiffness)')
    _log(log, f'compare: {n} instruments {names}, {plant_text}, naive gain {gain:.4f} A, '
              f'domains {domains}')

    # --- 1. calibration grasp on the load cell, per instrument ------------------------------
    # A current staircase (the naive map: current proportional to the master closing, no
    # feedback), slow ramps up: the pulley friction stays in its loading direction. A force
    # loop would overshoot and settle from above, where the stick-slip friction holds a
    # different tension than the model describes.
    _log(log, f'stage 1/{len(conditions) + 1}: calibration grasps (current staircase on the load cell)')
    jobs = []
    for k, config in enumerate(configs):
        params = load_params_file(config)
        csv_path = calibration_csv(params, out_dir / names[k] / 'calibration_master.csv')
        jobs.append({'spec': dict(config=config, sim_config=sims[k], duration=0.0,
                                  label=f'{names[k]}/calibration',
                                  controller='naive',
                                  controller_overrides={
                                      'naive_current_closed': calibration_current(params)},
                                  sim_overrides=scales[k],
                                  master_overrides={'trajectory': 'csv',
                                                    'trajectory_file': str(csv_path.resolve())},
                                  **scheduling),
                     'out_dir': str(out_dir / names[k] / 'calibration'),
                     'domain_id': domains[k], 'analyse': False, 'plot': False,
                     'calibration': True})
    calib_runs = _run_all(jobs, parallel, log)
    calibrated: list[Path | None] = []
    calibrations = []
    for k, (config, run) in enumerate(zip(configs, calib_runs)):
        params = load_params_file(config)
        try:
            if not run.get('completed', True):
                raise ValueError(run['problems'][0])
            fit = fit_instrument(params, read_log(run['bag']))
        except ValueError as exc:      # no calibration: its 'controlled' run is not done
            calibrated.append(None)
            calibrations.append({'completed': False, 'bag': run['bag'],
                                 'problems': [f'no calibration: {exc}'],
                                 'spoiled_attempts': run['spoiled_attempts']})
            _log(log, f'  {names[k]}: NO CALIBRATION ({exc})')
            continue
        path = out_dir / names[k] / f'{names[k]}_calibrated.yaml'
        path.write_text(calibrated_yaml(config, fit, run['bag']))
        calibrated.append(path)
        calibrations.append({**fit.as_dict(), 'completed': True, 'yaml': str(path),
                             'bag': run['bag'],
                             'problems': run.get('problems', []),
                             'spoiled_attempts': run['spoiled_attempts']})
        plant_mu = (load_params_file(sims[k]).pulley_friction_coefficient
                    * scales[k].get('friction_scale', 1.0))
        _log(log, f"  {names[k]}: mu {fit.before['pulley_friction_coefficient']:.4f} -> "
                  f"{fit.values['pulley_friction_coefficient']:.4f} +/- "
                  f"{fit.std_errors['pulley_friction_coefficient']:.4f} (plant "
                  f"{plant_mu:.4f})")

    # --- 2..5. the four conditions -------------------------------------------------------
    def spec_for(condition: str, k: int) -> dict:
        base = dict(config=configs[k], sim_config=sims[k], duration=task_duration,
                    label=f'{names[k]}/{condition}', sim_overrides=scales[k], **scheduling)
        if condition == 'controlled':
            base.update(config=calibrated[k], controller_overrides={'force_sensor_enabled': False})
        elif condition == 'uncalibrated':
            base.update(controller_overrides={'force_sensor_enabled': False})
        elif condition == 'sensor':
            base.update(controller_overrides={'force_sensor_enabled': True})
        else:
            base.update(controller='naive', controller_overrides={'naive_current_closed': gain})
        return base

    runs: dict[str, list[dict]] = {}
    for stage, condition in enumerate(conditions, start=2):
        _log(log, f'stage {stage}/{len(conditions) + 1}: {condition}')
        jobs = [{'spec': spec_for(condition, k),
                 'out_dir': str(out_dir / names[k] / condition), 'domain_id': domains[k],
                 'analyse': True, 'plot': True} for k in range(n)]
        # the calibrated condition of an instrument without a calibration cannot run
        skipped = {k: not_completed(jobs[k], f"not run: {calibrations[k]['problems'][0]}")
                   for k in range(n) if condition == 'controlled' and calibrated[k] is None}
        done = iter(_run_all([j for k, j in enumerate(jobs) if k not in skipped], parallel, log))
        runs[condition] = [skipped[k] if k in skipped else next(done) for k in range(n)]
        for k in skipped:
            _log(log, _done(jobs[k], skipped[k]))

    instruments = []
    for k in range(n):
        per = {'name': names[k], 'config': str(configs[k]), 'plant_file': str(sims[k]),
               'plant': scales[k],
               'calibration': calibrations[k], 'runs': {}}
        for condition in conditions:
            r = runs[condition][k]
            m = r['metrics'] or {}
            per['runs'][condition] = {
                'completed': r.get('completed', True),
                'steady_ratio': m.get('steady_ratio'), 'target_force': m.get('target_force'),
                'measured_force': m.get('measured_force'),
                'hold_error_rms': m.get('hold_error_rms'), 'plot': r['plot'], 'bag': r['bag'],
                'problems': r.get('problems', []), 'spoiled_attempts': r['spoiled_attempts'],
                'late_inputs': r.get('late_inputs') or {},
                'scheduling': r.get('scheduling') or {},
                'safe_state_entries': len(r.get('safe_state_entries') or [])}
        instruments.append(per)
    report: dict[str, Any] = {'instruments': instruments, 'conditions': list(conditions)}
    for condition in conditions:
        report[f'spread_{condition}'] = spread(
            [i['runs'][condition]['steady_ratio'] for i in instruments])
        clean = [i['runs'][condition]['steady_ratio'] for i in instruments
                 if not i['runs'][condition]['problems']]
        report[f'spread_{condition}_unspoiled'] = spread(clean) if len(clean) >= 2 else None
    report['runs_still_spoiled'] = (
        [f"{i['name']}/calibration: {i['calibration']['problems'][0]}"
         for i in instruments if i['calibration']['problems'] and i['calibration']['completed']]
        + [f"{i['name']}/{c}: {i['runs'][c]['problems'][0]}"
           for i in instruments for c in conditions
           if i['runs'][c]['problems'] and i['runs'][c]['completed']])
    # runs that no attempt completed (a node that never came up or died, a master that
    # answered no request): which instrument, which run, why
    report['runs_not_completed'] = (
        [f"{i['name']}/calibration: {i['calibration']['problems'][0]}"
         for i in instruments if not i['calibration']['completed']]
        + [f"{i['name']}/{c}: {i['runs'][c]['problems'][0]}"
           for i in instruments for c in conditions if not i['runs'][c]['completed']])
    report['naive_current_closed'] = gain
    report['plant_error'] = None if plants else plant_error
    report['plants'] = [str(p) for p in plants] if plants else None
    report['task_duration'] = task_duration
    report['wall_time'] = time.monotonic() - started
    report['out_dir'] = str(out_dir)
    _json_safe(report)
    report['plot'] = None
    if plot and list(conditions) == list(CONDITIONS):
        from grip_force_ros.lab.demo.plot import compare_plot
        report['plot'] = str(compare_plot(report, out_dir / 'compare.png'))
    (out_dir / 'compare.json').write_text(json.dumps(report, indent=1))
    return report


def _json_safe(obj: Any) -> Any:
    """Replace NaN by None in place (JSON has no NaN)."""
    if isinstance(obj, dict):
        for k, v in obj.items():
            obj[k] = _json_safe(v)
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            obj[i] = _json_safe(v)
    elif isinstance(obj, float) and not np.isfinite(obj):
        return None
    return obj


def format_report(report: dict[str, Any]) -> str:
    """Format a table: steady hold force / target per instrument and condition, then the spreads."""
    conditions = report.get('conditions', CONDITIONS)
    lines = [f"{'instrument':28s}" + ''.join(f'{c:>14s}' for c in conditions)]
    for inst in report['instruments']:
        cells = []
        for c in conditions:
            v = inst['runs'][c]['steady_ratio']
            cells.append(f'{v:14.3f}' if v is not None else f"{'n/a':>14s}")
        lines.append(f"{inst['name']:28s}" + ''.join(cells))
    lines.append(f"{'spread (max - min)':28s}" + ''.join(
        f"{report[f'spread_{c}']:14.3f}" if report[f'spread_{c}'] is not None else f"{'n/a':>14s}"
        for c in conditions))
    for item in report.get('runs_still_spoiled') or []:
        lines.append(f'spoiled by a starved node after {ATTEMPTS} attempts: {item}')
    for item in report.get('runs_not_completed') or []:
        lines.append(f'NOT COMPLETED: {item}')
    plants = (f"plants {', '.join(Path(p).name for p in report['plants'])}" if report.get('plants')
              else f"plants off by {report['plant_error']:.0%}")
    lines.append(f"(steady hold force / target; {plants}; "
                 f"{report['wall_time']:.0f} s; {report['out_dir']})")
    return '\n'.join(lines)
