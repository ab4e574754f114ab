"""The MRDLab rig: import, sign conventions, the estimator's input gate, held-out accuracy.

Uses the real data in ../shared/data/mis-tool-characterization (skipped when absent).
"""
import json
import math

import numpy as np
import pytest

from grip_force_ros.lab.cli import main as cli_main
from grip_force_ros.logs import read_csv
from grip_force_ros.lab.rig import (RigDataError, data_root, read_run, read_runs, run_files,
                                    to_contract_log)
from grip_force_ros.lab.rig import constants as C
from grip_force_ros.lab.rig.analysis import holdout_split
from grip_force_ros.lab.rig.estimator import (ALLOWED_INPUTS, FORBIDDEN_INPUTS, CableFrictionObserver,
                                              EstimatorError, LinearCurrentEstimator, dahl_direction,
                                              hold_observer, motor_side_inputs, rmse)

DATA = data_root() / 'Tool_4_Maryland_L_2'
needs_data = pytest.mark.skipif(not DATA.is_dir(), reason=f'rig data not found at {DATA}')


@pytest.fixture(scope='module')
def runs():
    if not DATA.is_dir():
        pytest.skip(f'rig data not found at {DATA}')
    return read_runs(DATA)


# -- reading and conventions -----------------------------------------------------------------
@needs_data
def test_read_a_slice_in_si_units():
    run = read_run(DATA / '11.TXT', rows=3000)
    assert len(run) == 3000
    assert (run.frequency_step, run.torque_step) == (1, 1)
    assert run.frequency_hz == pytest.approx(0.2) and run.torque_level_percent == pytest.approx(20.0)
    assert np.allclose(np.diff(run.t), C.SAMPLE_PERIOD, atol=1e-6) and run.t[0] == 0.0
    # first data row of 11.TXT: 0.000,0.00,-810.00,-0.054,880.00,-314.00,0.20,0.02,1259.00,0.00
    assert run.current[0] == pytest.approx(-0.054)
    assert run.jaw_torque[0] == pytest.approx(314.0 * 0.000039811)
    assert run.disk_torque[0] == pytest.approx(-810.0 * 0.000039811)
    assert run.jaw_angle[0] == pytest.approx((885.0 - 880.0) * 2 * math.pi / 4000.0)
    assert run.motor_angle[0] == 0.0 and run.motor_shaft_angle[0] == 0.0
    assert run.load_command[0] == pytest.approx(0.2)
    assert run.current_command[0] == pytest.approx(-0.02 * C.BACKEND_COMMAND_FULL_SCALE)


def test_bad_files_give_one_clear_error(tmp_path):
    bad_name = tmp_path / 'run.txt'
    bad_name.write_text('0,1,2\n')
    with pytest.raises(RigDataError, match='XY.TXT'):
        read_run(bad_name)
    short = tmp_path / '12.TXT'
    short.write_text('%header\n0.0,1,2\n0.001,1,2\n')
    with pytest.raises(RigDataError, match='10 columns'):
        read_run(short)
    empty = tmp_path / 'empty'
    empty.mkdir()
    with pytest.raises(RigDataError, match='no XY.TXT'):
        run_files(empty)
    with pytest.raises(RigDataError, match='not a directory'):
        run_files(tmp_path / 'missing')


@needs_data
def test_sign_conventions_found_in_the_data(runs):
    for run in runs:
        v = np.gradient(run.motor_angle, run.t)
        closing, opening = v > 0.2, v < -0.2
        # the resisting load makes closing harder: positive current while closing, and more of it
        assert np.mean(run.current[closing]) > 0 > np.mean(run.current[opening])
        assert abs(np.mean(run.current[closing])) > abs(np.mean(run.current[opening]))
        # the jaw opens when the motor angle falls (closing positive on both)
        assert np.corrcoef(run.motor_angle, run.jaw_angle)[0, 1] < -0.99
        # the gearbox output follows the input disk (same sign)
        assert np.corrcoef(run.motor_angle, run.motor_shaft_angle)[0, 1] > 0.999
        # the jaw holds a closing torque against the resisting motor
        assert np.all(np.percentile(run.jaw_torque, [5, 50]) > 0)
        assert np.min(run.jaw_angle) >= 0.0
    # the mean jaw torque grows with the resisting level, about 12 mN*m per 10 %
    means = {y: np.mean([r.jaw_torque.mean() for r in runs if r.torque_step == y]) for y in range(4)}
    steps = np.diff([means[y] for y in range(4)])
    assert np.all(steps > 0.010) and np.all(steps < 0.014)


@needs_data
def test_import_rig_writes_contract_csvs(tmp_path):
    out = tmp_path / 'csv'
    assert cli_main(['import-rig', str(DATA), '--out', str(out), '--rows', '500', '--json']) == 0
    files = sorted(out.glob('*.csv'))
    assert len(files) == 20 and (out / 'README.md').is_file()
    text = files[5].read_text()
    assert text.startswith('# Data: MRDLab/mis-tool-characterization') and 'ODbL' in text
    log = read_csv(files[5])
    for col in ('t', 'current', 'motor_angle', 'wrist_angle', 'jaw_angle', 'jaw_torque', 'object',
                'current_command', 'motor_shaft_angle', 'disk_torque'):
        assert col in log
    assert log['t'].size == 500 and np.all(log['wrist_angle'] == 0.0)
    assert set(log['object']) == {'rigid'}
    original = to_contract_log(read_run(DATA / f'{files[5].stem}.TXT', rows=500))
    for col in ('current', 'motor_angle', 'jaw_angle', 'jaw_torque'):
        assert np.allclose(log[col], original[col], rtol=1e-8, atol=1e-12)


# -- building blocks -------------------------------------------------------------------------
def test_dahl_state_follows_motion_and_sticks():
    angle = np.concatenate([np.linspace(0, 0.2, 201), np.full(50, 0.2), np.linspace(0.2, 0.0, 201)])
    s = dahl_direction(angle, 0.02)
    assert s[0] == 0.0 and s[200] > 0.99                    # 10 widths of closing motion
    assert np.all(s[201:251] == s[200])                     # no motion, no change
    assert s[-1] < -0.99 and np.all(np.abs(s) <= 1.0)
    # reversal: s crosses zero after about ln(2) widths of travel back
    back = np.flatnonzero(s[251:] < 0)[0] * 0.001
    assert back == pytest.approx(0.02 * math.log(2.0), abs=0.002)


def test_hold_observer_averages_while_sliding_and_holds_otherwise():
    rng = np.random.default_rng(3)
    z = 0.03 + 0.002 * rng.standard_normal(3000)
    w = np.ones(3000)
    w[1000:2000] = 0.0
    z[1000:2000] = 5.0                                      # garbage while stuck: ignored
    est = hold_observer(z, w, 0.01, initial=0.0)
    assert abs(est[999] - 0.03) < 0.001
    assert np.all(est[1000:2000] == est[999])
    assert abs(est[-1] - 0.03) < 0.001
    assert np.all(hold_observer(z, np.zeros(3000), 0.01, initial=0.02) == 0.02)


# -- the estimator -----------------------------------------------------------------------------
def _slice(run, seconds):
    n = int(seconds / C.SAMPLE_PERIOD)
    return to_contract_log(type(run)(**{k: (v[:n] if isinstance(v, np.ndarray) else v)
                                        for k, v in run.__dict__.items()}))


@needs_data
def test_estimator_never_reads_the_jaw_side(runs):
    train, test = holdout_split(runs)
    est = CableFrictionObserver().fit(train[::2])
    log = _slice(test[0], 8.0)
    reference = est.predict(log)
    rng = np.random.default_rng(7)
    corrupted = dict(log)
    for name in FORBIDDEN_INPUTS:
        if name in corrupted:
            corrupted[name] = rng.normal(0.0, 1e3, log['t'].size)
    assert set(FORBIDDEN_INPUTS) & set(corrupted) >= {'jaw_torque', 'jaw_angle', 'disk_torque',
                                                      'load_command'}
    assert np.array_equal(est.predict(corrupted), reference)
    # ... and the same prediction with the jaw side removed altogether
    motor_only = {k: v for k, v in log.items() if k in ALLOWED_INPUTS}
    assert np.array_equal(est.predict(motor_only), reference)
    assert np.array_equal(LinearCurrentEstimator().fit(train[:2]).predict(corrupted),
                          LinearCurrentEstimator().fit(train[:2]).predict(log))
    # but a motor-side column does change it
    moved = dict(log)
    moved['current'] = log['current'] + 0.01
    assert not np.allclose(est.predict(moved), reference)
    assert set(motor_side_inputs(corrupted)) <= set(ALLOWED_INPUTS)


def test_estimator_needs_the_motor_side():
    with pytest.raises(EstimatorError, match='current'):
        motor_side_inputs({'t': np.arange(3.0), 'motor_angle': np.zeros(3)})
    with pytest.raises(EstimatorError, match='before fit'):
        CableFrictionObserver().predict({'t': np.arange(3.0), 'current': np.zeros(3),
                                         'motor_angle': np.zeros(3)})


@needs_data
def test_held_out_rmse_beats_the_linear_fit_and_the_parameters_are_physical(runs):
    train, test = holdout_split(runs)
    assert {r.torque_step for r in train} == {0, 2} and {r.torque_step for r in test} == {1, 3}
    full = CableFrictionObserver().fit(train)
    linear = LinearCurrentEstimator().fit(train)
    err_full, err_lin = rmse(full, test), rmse(linear, test)
    assert err_full < 0.5 * err_lin
    assert err_full < 0.006                                  # N*m; 3.9 mN*m measured
    phys = {k: v for k, (v, _) in full.fit_result.physical.items()}
    std = {k: s for k, (_, s) in full.fit_result.physical.items()}
    assert 0.6 < phys['efficiency'] < 1.0                    # loses while driving
    assert 0.5 < phys['gain_Nm_per_A'] < 1.5
    assert phys['coulomb_Nm'] > 0.03                         # friction larger than the load
    assert all(np.isfinite(s) and s > 0 for s in std.values())


@needs_data
def test_realdata_command_quick_json(runs, capsys, tmp_path):
    subset = tmp_path / 'rig'           # the slowest and the fastest runs keep the test short
    subset.mkdir()
    for path in sorted(DATA.glob('[04]?.TXT')):
        (subset / path.name).symlink_to(path)
    assert cli_main(['realdata', str(subset), '--quick', '--json', '--out', str(tmp_path / 'rep')]) == 0
    result = json.loads(capsys.readouterr().out)
    assert (tmp_path / 'rep' / 'report.md').is_file()
    assert len(list((tmp_path / 'rep').glob('realdata_*.png'))) == 4
    assert result['published_rmse_mNm'] == pytest.approx(4.42)
    names = [e['name'] for e in result['estimators']]
    assert names == ['linear', 'cable_friction_observer']
    lin, full = result['estimators']
    assert full['holdout_rmse_mNm'] < lin['holdout_rmse_mNm']
    assert set(result['split']['holdout']['test']) == {'01', '03', '41', '43'}
    shares = [r['share_of_gap'] for r in result['regions'] if r['family'] == 'motion']
    assert sum(shares) == pytest.approx(1.0, abs=1e-3)
    assert {row['effect'] for row in result['effects']['add_one']} >= {'backlash', 'sensor_delay'}


@needs_data
@pytest.mark.parametrize('changes', [{}, {'current_delay_s': 0.004, 'slow_hysteresis_width': 0.2,
                                          'friction_map_order': 3, 'backlash_angle': 'motor_angle'},
                                     {'hysteresis': False}])
def test_streaming_observer_gives_the_batch_numbers(runs, changes):
    from grip_force_ros.lab.rig.streaming import StreamingJawTorqueObserver
    train, test = holdout_split(runs)
    est = CableFrictionObserver(**changes).fit(train[::3])
    log = _slice(test[3], 6.0)
    batch = est.predict(log)
    live = StreamingJawTorqueObserver(est, dt=C.SAMPLE_PERIOD)
    stream = np.array([live.step(i, x, xs) for i, x, xs in
                       zip(log['current'], log['motor_angle'], log['motor_shaft_angle'])])
    assert np.allclose(stream, batch, rtol=0, atol=1e-9)
    live.reset()
    assert live.step(log['current'][0], log['motor_angle'][0], log['motor_shaft_angle'][0]) == \
        pytest.approx(stream[0], abs=1e-12)


from hypothesis import given, settings as hyp_settings, strategies as st  # noqa: E402


@hyp_settings(max_examples=60, deadline=None)
@given(steps=st.lists(st.floats(-0.05, 0.05, allow_nan=False), min_size=1, max_size=200),
       width=st.floats(0.001, 0.1))
def test_dahl_state_is_bounded_and_moves_with_each_step(steps, width):
    angle = np.cumsum([0.0] + steps)
    s = dahl_direction(angle, width)
    assert np.all(np.abs(s) <= 1.0)
    ds = np.diff(s)
    moves = np.diff(angle)
    # the state moves towards the sign of each displacement and never away from it
    assert np.all(ds[moves > 0] >= -1e-12) and np.all(ds[moves < 0] <= 1e-12)
    assert np.all(ds[moves == 0] == 0.0)
