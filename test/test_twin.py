"""`grip-force twin`: an instrument file identified from the MRDLab rig runs (lab/rig/twin.py).

The twin of ``Tool_4_Maryland_L_2`` must give back what the rig analysis found by hand
(config/maryland_forceps.yaml: Coulomb friction 75 +- 3 mN*m at the jaw, a restoring spring
of about 20 mN*m over the stroke), beat the raw-current estimator held out, and be an
instrument file the sim and the controller use: a needle grasp on a plant that is the twin,
by a controller told the twin (on the load cell), holds its target.
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from grip_force_ros.lab.rig.analysis import holdout_split, rmse_of
from grip_force_ros.lab.rig.estimator import LinearCurrentEstimator
from grip_force_ros.lab.rig.transfer import load_folder
from grip_force_ros.params import load_params_file, read_params_yaml

FOLDER = 'Tool_4_Maryland_L_2'
BASE = Path(__file__).resolve().parents[1] / 'config' / 'maryland_forceps.yaml'


def _twin(*args):
    return subprocess.run([sys.executable, '-m', 'grip_force_ros.lab.cli', 'twin', *args],
                          capture_output=True, text=True, timeout=600)


@pytest.fixture(scope='module')
def twin(tmp_path_factory):
    out = tmp_path_factory.mktemp('twin') / 'maryland_twin.yaml'
    proc = _twin('--rig', FOLDER, '--base', str(BASE), '--out', str(out), '--json')
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout), out


def test_the_twin_gives_back_the_rigs_friction_and_spring(twin):
    answer, _ = twin
    p = answer['parameters']
    for name, entry in p.items():
        assert set(entry) >= {'value', 'std', 'unit'}, name
        assert entry['std'] is None or (np.isfinite(entry['std']) and entry['std'] >= 0), name
    assert p['jaw_coulomb_friction']['unit'] == 'N*m'
    assert 0.065 < p['jaw_coulomb_friction']['value'] < 0.085          # 75 +- 3 mN*m by hand
    assert p['jaw_coulomb_friction']['std'] < 0.005
    stroke = 2 * (p['jaw_spring_rest_angle']['value'])                 # the jaw's stroke, rad
    span = -p['jaw_spring_slope']['value'] * stroke                    # N*m over the stroke
    assert 0.015 < span < 0.025                                        # 19.7 +- 1.1 mN*m by hand
    assert p['jaw_viscous_friction']['value'] >= 0.0
    assert any('viscous' in note for note in answer['notes'])          # the negative fit, said
    assert 'jaw_moment_arm_tip' in answer['assumed']


def test_the_twin_beats_the_raw_current_held_out(twin):
    answer, _ = twin
    runs = load_folder(FOLDER).runs
    train = [r for r in runs if r.torque_step % 2 == 0]
    test = [r for r in runs if r.torque_step % 2 == 1]
    assert (train, test) == tuple(holdout_split(runs))                 # the realdata split here
    linear = LinearCurrentEstimator().fit(train)
    baseline = rmse_of({r.name: linear.predict(r) for r in test}, test)
    assert answer['heldout_rmse'] < 0.5 * baseline
    assert answer['heldout_rmse_after_startup'] <= answer['heldout_rmse']


def test_the_twin_file_is_an_instrument_the_loop_holds_with(twin):
    from grip_force_ros.control import GripController
    from grip_force_ros.lab.closed_loop import closed_loop_step
    from grip_force_ros.sim.plant import InstrumentSim
    from grip_force_ros.trajectories import needle_grasp
    answer, out = twin
    params = load_params_file(out)
    assert params.instrument_name == 'maryland_twin'
    assert params.jaw_coulomb_friction == pytest.approx(answer['parameters']['jaw_coulomb_friction']['value'],
                                                        rel=1e-5)
    base = read_params_yaml(BASE)
    assert params.jaw_moment_arm_tip == base['jaw_moment_arm_tip']    # assumed: kept
    assert out.read_text().startswith('# Instrument twin (')
    # On the load cell: sensorless, a grasp held in stick is anywhere in the jaw friction's
    # band (75 mN*m at a 12 mm arm: +-6 N), whatever the file (docs/control.md).
    sim = InstrumentSim(params, obj='needle', seed=3)
    ctrl = GripController(params.replace(force_sensor_enabled=True))
    inputs, traj, rows = ctrl.new_inputs(), needle_grasp(), []
    for k in range(2800):
        t = k * 1e-3
        _, step = closed_loop_step(sim, ctrl, inputs, t, traj.angle(t), 1e-3)
        if t >= 2.3:                                      # the end of the hold
            rows.append((step.target_force, sim.truth()['grip_force']))
    target, force = np.mean(rows, axis=0)
    assert target > 0.5 and abs(force - target) / target < 0.05


def test_a_bad_base_or_folder_is_an_error_with_exit_1(tmp_path):
    bad = tmp_path / 'bad.yaml'
    bad.write_text('/**:\n  ros__parameters:\n    drum_radius: -1.0\n')
    proc = _twin('--rig', FOLDER, '--base', str(bad), '--out', str(tmp_path / 'x.yaml'))
    assert proc.returncode == 1 and 'drum_radius' in proc.stderr
    proc = _twin('--rig', str(tmp_path), '--base', str(BASE), '--out', str(tmp_path / 'x.yaml'))
    assert proc.returncode == 1 and proc.stderr.startswith('error:')
    assert not (tmp_path / 'x.yaml').exists()
