"""Loop design (lab/tune.py, python-control) and `grip-force tune`.

The margins claimed in docs/control.md and in each YAML are checked on the gains the YAML
carries, for every plant variant (nominal, cable stiffness and pulley friction +-20%), with
the gains the controller runs (the schedule on the state rate) at every rate of the grid.
"""
import argparse
import json
import math
from pathlib import Path

import numpy as np
import pytest

from grip_force_ros.lab import tune
from grip_force_ros.params import load_params_file, make_params

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = sorted((ROOT / 'config').glob('*.yaml'))


@pytest.mark.parametrize('path', CONFIGS, ids=[p.stem for p in CONFIGS])
def test_yaml_gains_meet_the_claimed_margins(path):
    from grip_force_ros.params import read_params_yaml
    assert 'force_ki' in read_params_yaml(path), (
        f'{path.name} carries no controller gains: run `./dev tune --config config/{path.name}` '
        'and add the printed gains to the YAML')
    params = load_params_file(path)
    result = tune.analyse(params)
    loops = ('force_sensor', 'force_estimate', 'jaw')
    rates = {r.rate_hz for r in result.reports}
    assert rates == set(tune.analysis_rates(params)) >= set(tune.GRID_RATES)
    assert min(rates) == 100.0 and max(rates) == 1500.0
    # below the design rate the schedule shrinks every loop's crossover; at and above it, not
    for r in result.reports:
        assert (r.gain_scale < 1.0) == (r.rate_hz < params.gain_design_rate), r
    assert len(result.reports) == len(tune.analysis_rates(params)) * sum(
        len(tune.loop_variants(loop)) for loop in loops)
    for r in result.reports:
        assert r.stable, r
        assert r.gain_margin_db >= tune.CLAIM_GM_DB, r
        assert r.phase_margin_deg >= tune.CLAIM_PM_DEG, r
        assert r.bandwidth_hz > 0.5, r


def test_margins_agree_with_closed_loop_poles_and_detect_a_bad_design():
    params = make_params({})
    good = tune.analyse(params, loops=('jaw',)).reports[0]
    assert good.stable and good.phase_margin_deg >= 45
    # ten times the jaw gain is beyond the gain margin: both tools must say so
    gm = 10 ** (good.gain_margin_db / 20)
    bad = params.replace(jaw_kp=params.jaw_kp * gm * 1.5, jaw_kd=params.jaw_kd * gm * 1.5,
                         jaw_ki=params.jaw_ki * gm * 1.5)
    r = tune.analyse(bad, loops=('jaw',)).reports[0]
    assert not r.stable


def test_gains_designed_for_1khz_alone_fail_at_the_dvrk_rate():
    """The rate check and the schedule are not vacuous: the paper's gains of the 1 kHz-only
    design (before the controller stepped on the measured time) meet the margins at 1 kHz and,
    run unscheduled (gain_design_rate 100 Hz: scale 1 everywhere), are unstable at 100 Hz
    states, the dVRK's ROS rate; the stick band's unloading edge fails their force gains at
    1 kHz. The paper's jaw gains are that design's: scheduled, they meet the margins at 100 Hz."""
    paper = load_params_file(ROOT / 'config' / 'paper_needle_driver.yaml')
    old = paper.replace(force_kp=0.0118, force_ki=8.83, jaw_kp=0.369, jaw_kd=0.00059)
    fast = tune.analyse(old, rates=(1000.0,))
    assert all(r.stable for r in fast.reports if r.variant != 'unloading edge')
    assert not all(r.phase_margin_deg >= tune.CLAIM_PM_DEG for r in fast.reports)
    slow = tune.analyse(old.replace(gain_design_rate=100.0), rates=(100.0,))
    assert not all(r.stable for r in slow.reports if r.loop == 'jaw')
    assert (paper.jaw_kp, paper.jaw_kd) == (old.jaw_kp, old.jaw_kd)
    scheduled = tune.analyse(paper, rates=(100.0,), loops=('jaw',))
    assert all(r.stable and r.phase_margin_deg >= tune.CLAIM_PM_DEG for r in scheduled.reports)


def test_plant_static_gain_matches_the_model():
    from grip_force_ros.model import GripForceModel
    params = load_params_file(ROOT / 'config' / 'paper_needle_driver.yaml')
    d = tune.plant_data(params)
    m = GripForceModel(params)
    slope = (m.grip_force_scalar(0.3, 0.0, 0.05, 'needle')
             - m.grip_force_scalar(0.2, 0.0, 0.05, 'needle')) / 0.1
    assert d.force_per_amp == pytest.approx(slope, rel=1e-6)
    # the DC gain of the linear force plant (load cell) is that slope too
    import control
    plant = control.ss(*tune.plant_statespace(d, 'force_sensor'))
    assert float(control.dcgain(plant)) == pytest.approx(slope, rel=1e-3)


def test_pid_transfer_function_matches_the_pid_class():
    """The analysed controller is exactly the one that runs."""
    import control
    from grip_force_ros.control import PID
    kp, ki, kd, tf, T = 0.3, 4.0, 0.002, 0.002, 1e-3
    pid = PID(kp, ki, kd, tf, T, tracking_time=1e9, integral_limit=1e9)
    pid.preset(0.0, 0.0, 0.0)          # zero initial state, as the transfer function assumes
    rng = np.random.default_rng(0)
    e = rng.standard_normal(200)
    out = []
    for x in e:                     # error = setpoint - measurement with measurement = -x
        u = pid.update(0.0, -x)
        pid.track(u, u)
        out.append(u)
    resp = control.forced_response(tune.pid_tf(kp, ki, kd, tf, T), T=np.arange(200) * T, U=e)
    assert np.allclose(out, np.asarray(resp.outputs).ravel(), atol=1e-9)


def test_design_meets_margins_on_the_paper_instrument():
    """The design (gains at gain_design_rate and the schedule's knees) meets the margins over
    the grid and is what the paper's YAML carries (the YAML is tune's output, not hand-edited)."""
    from grip_force_ros.params import read_params_yaml
    params = load_params_file(ROOT / 'config' / 'paper_needle_driver.yaml')
    result = tune.design(params)
    for loop in ('force_sensor', 'force_estimate', 'jaw'):
        gm, pm = result.worst(loop)
        assert gm >= tune.CLAIM_GM_DB and pm >= tune.CLAIM_PM_DEG, loop
    assert result.gains['force_ki'] > 0 and result.gains['jaw_kp'] > 0
    yaml = read_params_yaml(ROOT / 'config' / 'paper_needle_driver.yaml')
    assert result.gains == {key: yaml[key] for key in result.gains}


def test_cli_prints_json_and_writes_the_step_plot(tmp_path, capsys):
    from grip_force_ros.lab.cli import tune as cli
    parser = argparse.ArgumentParser()
    cli.add_arguments(parser)
    args = parser.parse_args(['--config', str(ROOT / 'config' / 'paper_needle_driver.yaml'),
                              '--json', '--out', str(tmp_path), '--analyse-only'])
    assert cli.run(args) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc['margins_met'] is True
    worst_pm = min(v['phase_margin_deg'] for loop in doc['loops'].values() for v in loop.values())
    assert worst_pm >= tune.CLAIM_PM_DEG
    png = Path(doc['plot'])
    assert png.exists() and png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n' and png.stat().st_size > 20_000
    steps = doc['settling_time_5pct_s']
    assert math.isfinite(steps['jaw (PID only)']) and steps['jaw (PID only)'] < 0.1


def test_margins_agree_with_python_control():
    """tune.margins (grid + brentq) == control.margin on a dense FRD, every loop and variant."""
    import warnings

    import control
    params = load_params_file(ROOT / 'config' / 'paper_needle_driver.yaml')
    period = 1.0 / params.expected_state_rate
    for loop in ('force_sensor', 'force_estimate', 'jaw'):
        for variant in ('nominal', 'stiffness x0.8', 'friction x1.2'):
            lt = tune.loop_transfer(params, loop, variant)
            gm_db, pm, _, _ = tune.margins(lt, period)
            with warnings.catch_warnings():
                warnings.simplefilter('ignore', UserWarning)
                gm, pm_ref, _, _ = control.margin(control.frd(lt, tune._freq_grid(period, 400)))
            assert gm_db == pytest.approx(20 * math.log10(gm), abs=0.05), (loop, variant)
            assert pm == pytest.approx(pm_ref, abs=0.2), (loop, variant)
