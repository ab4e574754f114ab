"""The gain schedule on the state rate (control/schedule.py) and the gains the controller runs.

The schedule's margins over the rate grid, for every shipped YAML, are checked in
test_tune.py (test_yaml_gains_meet_the_claimed_margins: the analysis runs the scheduled
gains at each rate); here: the rule itself and its use by the controller.
"""
from pathlib import Path

import pytest

from grip_force_ros.control import GripController
from grip_force_ros.control.schedule import bandwidth_scale, scheduled_gains
from grip_force_ros.params import load_params_file

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope='module')
def paper():
    return load_params_file(ROOT / 'config' / 'paper_needle_driver.yaml')


def test_scale_is_one_at_and_above_the_design_rate_and_falls_with_the_rate():
    assert bandwidth_scale(1000.0, 1000.0, 500.0) == 1.0
    assert bandwidth_scale(1500.0, 1000.0, 500.0) == 1.0
    scales = [bandwidth_scale(r, 1000.0, 500.0) for r in (100.0, 250.0, 500.0, 999.0)]
    assert scales == sorted(scales) and 0.0 < scales[0] < scales[-1] < 1.0
    # knee 500 Hz: s = (1/500 + 1/1000) / (1/500 + 1/100) = 0.003 / 0.012
    assert bandwidth_scale(100.0, 1000.0, 500.0) == pytest.approx(0.25, rel=1e-12)
    # far below the knee the crossover is proportional to the rate, far above it hardly moves
    assert bandwidth_scale(100.0, 1000.0, 1e9) == pytest.approx(0.1, rel=1e-6)
    assert bandwidth_scale(100.0, 1000.0, 1e-3) == pytest.approx(1.0, rel=1e-4)
    with pytest.raises(ValueError, match='knee'):
        bandwidth_scale(100.0, 1000.0, 0.0)


def test_controller_runs_the_designed_gains_at_1khz(paper):
    assert paper.expected_state_rate == paper.gain_design_rate == 1000.0
    ctrl = GripController(paper)
    g = ctrl.gains
    assert (g.force_scale, g.jaw_scale) == (1.0, 1.0)
    assert g.as_params() == {k: paper[k] for k in g.as_params()}
    assert (ctrl.force_pid.kp, ctrl.force_pid.ki) == (paper.force_kp, paper.force_ki)
    assert (ctrl.jaw_pid.kp, ctrl.jaw_pid.ki, ctrl.jaw_pid.kd) == (paper.jaw_kp, paper.jaw_ki, paper.jaw_kd)
    status = ctrl.status()
    assert status['gain_scale'] == 'force 1.000, jaw 1.000'
    assert 'designed at 1000 Hz, states expected at 1000 Hz' in status['gain_schedule']


def test_controller_schedules_the_gains_at_100hz(paper):
    """dVRK rate: each loop's crossover scaled by s, the PI zero and derivative time with it."""
    p = paper.replace(expected_state_rate=100.0, watchdog_timeout=0.05)
    ctrl = GripController(p)
    g = ctrl.gains
    s_f = (1 / paper.force_schedule_knee + 1e-3) / (1 / paper.force_schedule_knee + 1e-2)
    s_j = (1 / paper.jaw_schedule_knee + 1e-3) / (1 / paper.jaw_schedule_knee + 1e-2)
    assert (g.force_scale, g.jaw_scale) == (pytest.approx(s_f), pytest.approx(s_j))
    assert 0.15 < g.force_scale < 0.3 and 0.15 < g.jaw_scale < 0.3     # knees 680, 820 Hz
    # force: static plant over the band -> kp kept, ki * s, kd / s
    assert ctrl.force_pid.kp == pytest.approx(paper.force_kp)
    assert ctrl.force_pid.ki == pytest.approx(paper.force_ki * s_f)
    # jaw: an integrator over the band -> kp * s, ki * s^2, kd kept
    assert ctrl.jaw_pid.kp == pytest.approx(paper.jaw_kp * s_j)
    assert ctrl.jaw_pid.ki == pytest.approx(paper.jaw_ki * s_j ** 2)
    assert ctrl.jaw_pid.kd == pytest.approx(paper.jaw_kd)
    # the derivative filters keep their number of state periods (10x the period, 10x the time)
    assert g.jaw.filter_time == pytest.approx(10.0 * paper.jaw_derivative_filter_time)
    assert g.force.filter_time == pytest.approx(10.0 * paper.force_derivative_filter_time)
    assert ctrl.status()['gain_scale'] == f'force {s_f:.3f}, jaw {s_j:.3f}'
    assert scheduled_gains(p) == g


@pytest.mark.parametrize('path', sorted((ROOT / 'config').glob('*.yaml')), ids=lambda p: p.stem)
def test_every_yaml_designs_at_1khz_with_knees_in_range(path):
    """Each shipped instrument carries its design rate and knees (tune's output)."""
    from grip_force_ros.params import read_params_yaml
    raw = read_params_yaml(path)
    assert raw['gain_design_rate'] == 1000.0
    for key in ('force_schedule_knee', 'jaw_schedule_knee'):
        assert 100.0 <= raw[key] <= 1.0e5, key
