"""The estimator under O'Neill et al. 2018's protocol (lab/rig/oneill.py), beside the published 4.42 mN*m.

The split is of individual samples (neighbours of one grasp on both sides), so the figure is
for comparing with the paper; the fit must still never read a test sample's jaw torque.
"""
from dataclasses import replace

import numpy as np
import pytest

from grip_force_ros.lab.rig import oneill
from grip_force_ros.lab.rig.estimator import CableFrictionObserver
from grip_force_ros.lab.rig.transfer import load_folder
from grip_force_ros.lab.rig.twin import TWIN_SETTINGS


@pytest.fixture(scope='module')
def runs():
    return load_folder(oneill.FOLDER).runs


def test_the_split_is_70_15_15_of_the_inner_samples_and_mixes_neighbours(runs):
    labels = oneill.split(runs, seed=3)
    counts = np.bincount(np.concatenate([lab[lab >= 0] for lab in labels]), minlength=3)
    assert counts / counts.sum() == pytest.approx(oneill.SHARES, abs=1e-4)
    for run, lab in zip(runs, labels):
        assert ((lab >= 0) == oneill.inner_samples(run)).all()      # the ends are dropped
    neighbours = labels[0][labels[0] >= 0]
    assert np.mean(neighbours[1:] != neighbours[:-1]) > 0.3          # a sample split, not a run split
    assert all((a == b).all() for a, b in zip(labels, oneill.split(runs, seed=3)))   # seeded


def test_the_fit_never_reads_a_test_samples_torque(runs):
    labels = oneill.split(runs[:6], seed=0)
    masks = [lab == 0 for lab in labels]
    fitted = CableFrictionObserver(TWIN_SETTINGS).fit(runs[:6], masks=masks)
    spoiled = [replace(r, jaw_torque=np.where(lab == 0, r.jaw_torque, 5.0))
               for r, lab in zip(runs[:6], labels)]
    again = CableFrictionObserver(TWIN_SETTINGS).fit(spoiled, masks=masks)
    assert again.coefficients == pytest.approx(fitted.coefficients, rel=1e-9, abs=1e-12)


def test_the_protocols_figure_stands_beside_the_published_one():
    result = oneill.score(seeds=(7, 8))
    assert result['published_rmse_mNm'] == 4.42 and len(result['seeds']) == 2
    for row in result['seeds']:
        assert row['scored_test_samples'] > 10000
        assert row['test_rmse_mNm'] < 6.0                            # measured 4.45-4.51 on seeds 0-4
        assert row['test_rmse_mNm'] < 0.6 * row['linear_test_rmse_mNm']
    assert result['worst_test_rmse_mNm'] >= result['mean_test_rmse_mNm']
