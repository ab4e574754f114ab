"""The headline safety figure in CI: calibrated, sensorless, three instruments, plants 20 % off.

``grip-force demo --compare-instruments`` (README, "The safety point, measured") runs four
conditions on three instruments; this test runs its calibration grasps and the
``controlled`` condition only (calibrated YAML, no force sensor), with a shorter task, all
through the real node processes. Each simulated plant has its pulley friction and cable
stiffness 20 % off its YAML (alternating signs); the controller is not told and only the
calibration grasp on the load cell tells the fit.

Goal: spread of the steady hold force / target over the three instruments <= 0.03 (the
product's requirement; README: 0.018 and 0.011 in two full-length runs). A run spoiled in
its hold phase (an input lost beyond its watchdog, a topic silent 100 ms) is redone at most
twice by the comparison itself (``demo.compare.ATTEMPTS``); a third spoiled run fails here
with its cause.
"""
import math

import pytest

from grip_force_ros.lab.demo.compare import ATTEMPTS, compare_instruments

pytestmark = [pytest.mark.ros, pytest.mark.slow]

#: The product's goal for the calibrated sensorless spread (max - min of force / target).
SPREAD_GOAL = 0.03
#: Task length of each run (s): the needle grasp at time_scale 0.8 instead of the
#: comparison's 1.2 (6 s); the steady window is the last 60 % of the 1.2 s hold.
TASK = 4.0


@pytest.mark.timeout(900)
def test_calibrated_sensorless_spread_on_three_instruments_with_plants_20_percent_off(tmp_path):
    report = compare_instruments(tmp_path / 'compare', conditions=('controlled',),
                                 task_duration=TASK, plot=False)
    names = [i['name'] for i in report['instruments']]
    assert len(names) == 3 and report['plant_error'] == pytest.approx(0.2)
    scales = {(i['plant']['friction_scale'], i['plant']['stiffness_scale'])
              for i in report['instruments']}
    assert scales == {(0.8, 1.2), (1.2, 0.8)}                  # every plant 20 % off
    assert not report['runs_still_spoiled'], (
        f'spoiled {ATTEMPTS} times: ' + '; '.join(report['runs_still_spoiled']))
    assert not report['runs_not_completed'], '; '.join(report['runs_not_completed'])
    ratios = {i['name']: i['runs']['controlled']['steady_ratio'] for i in report['instruments']}
    fits = {i['name']: i['calibration']['fitted']['pulley_friction_coefficient']
            for i in report['instruments']}
    print(f"calibrated sensorless: {ratios}, spread {report['spread_controlled']:.4f}; "
          f"fitted mu {fits}; {report['wall_time']:.0f} s")
    assert all(r is not None and math.isfinite(r) for r in ratios.values()), ratios
    assert report['spread_controlled'] <= SPREAD_GOAL, (ratios, report['spread_controlled'])


def test_plants_mismatched_with_configs_are_refused(tmp_path):
    from grip_force_ros.params import instrument_path
    paper = instrument_path('paper_needle_driver')
    with pytest.raises(ValueError, match='one controller file per plant'):
        compare_instruments(tmp_path, plants=[paper, paper], configs=[paper], conditions=('sensor',))


@pytest.mark.timeout(600)
def test_plants_run_as_given_with_their_own_files_on_the_load_cell(tmp_path):
    """--plants: the sims run the given files (no perturbation), each controller its plant's
    file by default; on the load cell both hold the target, the one with jaw friction too."""
    from grip_force_ros.params import instrument_path, load_params_file, rewrite_instrument_file
    paper = instrument_path('paper_needle_driver')
    rubbing = tmp_path / 'paper_with_jaw_friction.yaml'
    rewrite_instrument_file(paper, rubbing, {'jaw_coulomb_friction': (0.01, 'test plant'),
                                             'instrument_name': ('paper_rubbing', 'test plant')},
                            '# the paper needle driver with 10 mN*m of Coulomb friction at the jaw')
    report = compare_instruments(tmp_path / 'compare', plants=[paper, rubbing], conditions=('sensor',),
                                 task_duration=TASK, plot=False)
    assert report['plants'] == [str(paper), str(rubbing)] and report['plant_error'] is None
    assert not report['runs_not_completed'], '; '.join(report['runs_not_completed'])
    assert not report['runs_still_spoiled'], '; '.join(report['runs_still_spoiled'])
    for inst, plant in zip(report['instruments'], (paper, rubbing)):
        assert inst['plant'] == {} and inst['plant_file'] == str(plant) == inst['config']
        assert abs(inst['runs']['sensor']['steady_ratio'] - 1.0) < 0.03, inst['runs']['sensor']
    assert load_params_file(rubbing).jaw_coulomb_friction == 0.01
