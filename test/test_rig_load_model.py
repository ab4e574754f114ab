"""The load model of the rig transfer estimator: a held load's level plus its shape along the stroke.

Plain pytest on synthetic numbers (no rig data needed): the fit reproduces a known shape and
a sign-inverting fit is clipped. The streaming observer's load model against the batch one:
``test_rig_transfer.py::test_streaming_observer_with_the_load_dependent_efficiency``.
"""
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from grip_force_ros.lab.rig.estimator import EstimatorError, LoadModel, ObserverSettings

SHAPE_CONSTANT = (0.004, -0.003, 0.001, 0.002, 0.0005)     # N*m: s, P1, P2, s*P1, 1
SHAPE_PROPORTIONAL = (-0.05, 0.12)                          # per unit of level: s, P1


def _strokes(levels, seed=0, n=4000):
    """Synthetic runs: a sine stroke (x), its direction (s), a constant level per run (N*m)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 1e-3
    x = np.sin(2 * np.pi * 0.5 * t + rng.uniform(0, 2 * np.pi))
    s = np.sign(np.gradient(x))
    truth = LoadModel(SHAPE_CONSTANT, SHAPE_PROPORTIONAL)
    runs = []
    for level in levels:
        offset, scale = truth.terms(s, x)
        runs.append((level * scale + offset, s, x))
    return runs


@given(st.lists(st.floats(0.01, 0.12), min_size=3, max_size=6, unique=True),
       st.integers(0, 2 ** 16))
@settings(max_examples=25, deadline=None)
def test_the_fit_recovers_a_known_shape(levels, seed):
    """The fit takes a run's level as its mean torque after the start; noise-free runs at three
    or more levels are then reproduced exactly (to 1e-9 N*m) from their mean."""
    runs = _strokes(levels, seed)
    fitted = LoadModel.fit(runs)
    for tau, s, x in runs:
        level = float(np.mean(tau))
        offset, scale = fitted.terms(s, x)
        assert np.allclose(level * scale + offset, tau, rtol=0, atol=1e-9)
    assert fitted.residual_std < 1e-9
    named = fitted.to_json()                                 # the transfer JSON's load_model
    assert tuple(named['constant_Nm'].values()) == fitted.constant
    assert tuple(named['proportional_per_level'].values()) == fitted.proportional


def test_a_fit_that_would_invert_the_load_is_clipped():
    model = LoadModel((0.0,) * 5, (-2.0, 0.0))            # 1 - 2*s < 0 on the closing branch
    _, scale = model.terms(np.array([1.0, -1.0]), np.zeros(2))
    assert scale[0] == pytest.approx(LoadModel.MIN_SCALE) and scale[1] == pytest.approx(3.0)


def test_no_training_samples_is_an_error():
    with pytest.raises(EstimatorError):
        LoadModel.fit([(np.array([]), np.array([]), np.array([]))])
    with pytest.raises(EstimatorError):
        ObserverSettings(load_model=True, hysteresis=False)
