"""Reference outputs of the model, the sim and the closed loop, for the bit-identity test.

``compute(config_dir)`` evaluates, for every shipped instrument file with its jaw friction
terms at zero, the vectorised forward and inverse, the scalar fast path, the stick band over
a current history, and a closed loop (sensorless controller on the simulated instrument,
plain and with the sim's ``pivot_coulomb_friction`` effect). It uses only the API that
existed before the jaw friction terms, so the same script run on the code without them wrote
``test/data/model_golden.npz``::

    cd <checkout without the terms> && .venv/bin/python <this file> --config-dir config --out X.npz

and ``test/test_jaw_friction.py`` compares today's code with it by ``==``.
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

#: Instrument files (config/), with their jaw friction terms set to 0 by the test.
CONFIGS = ('paper_needle_driver', 'long_jaw_grasper', 'four_pulley_needle_driver', 'maryland_forceps')
#: Parameters the jaw friction added to the schema: 0 (off) in the comparison.
JAW_TERMS = ('jaw_coulomb_friction', 'jaw_coulomb_friction_slope', 'jaw_spring_torque',
             'jaw_spring_slope', 'jaw_spring_curvature', 'jaw_viscous_friction',
             'jaw_efficiency_load_gain')
OBJECTS = ('needle', 'rigid', 'tissue')
SAMPLES = 48
LOOP_STEPS = 400


def load(config_dir: Path, name: str):
    """Return the instrument's parameters with every jaw friction term at 0 (where the schema has them)."""
    from grip_force_ros.params import load_params_file
    p = load_params_file(str(Path(config_dir) / f'{name}.yaml'))
    off = {k: 0.0 for k in JAW_TERMS if hasattr(p, k)}
    return p.replace(**off) if off else p


def compute(config_dir: Path) -> dict[str, np.ndarray]:
    """Return the reference arrays by key ``<config>/<quantity>``."""
    from grip_force_ros.control import GripController
    from grip_force_ros.lab.closed_loop import closed_loop_step
    from grip_force_ros.model import GripForceModel, hysteretic_grip_force
    from grip_force_ros.sim.plant import InstrumentSim

    out = {}
    for name in CONFIGS:
        p = load(config_dir, name)
        m = GripForceModel(p)
        rng = np.random.default_rng(48)
        current = rng.uniform(0.0, p.max_current, SAMPLES)
        wrist = rng.uniform(-p.wrist_angle_limit, p.wrist_angle_limit, SAMPLES)
        jaw = rng.uniform(max(p.jaw_angle_min, 0.0), 1.2, SAMPLES)
        mv, jv = rng.uniform(-20, 20, SAMPLES), rng.uniform(-20, 20, SAMPLES)
        for obj in OBJECTS:
            r = m.forward(current, wrist, jaw, obj, mv, jv)
            for field in ('grip_force', 'pull_out_force', 'jaw_torque', 'efficiency', 'drum_tension'):
                out[f'{name}/{obj}/forward/{field}'] = np.asarray(getattr(r, field))
            out[f'{name}/{obj}/inverse'] = m.inverse(r.grip_force, wrist, jaw, obj, mv, jv)
            out[f'{name}/{obj}/inverse_rest'] = m.inverse(r.grip_force, wrist, jaw, obj)
            scalar = [m.grip_force_scalar(float(i), float(w), float(j), obj)
                      for i, w, j in zip(current, wrist, jaw)]
            out[f'{name}/{obj}/grip_force_scalar'] = np.array(scalar)
            out[f'{name}/{obj}/current_for_force_scalar'] = np.array(
                [m.current_for_force_scalar(f, float(w), float(j), obj)
                 for f, w, j in zip(scalar, wrist, jaw)])
        history = p.max_current * np.abs(np.sin(np.linspace(0.0, 3.0 * math.pi, 200)))
        force, tension = hysteretic_grip_force(m, history, 0.1, 0.3, 'needle')
        out[f'{name}/stick_band/force'] = np.asarray(force)
        out[f'{name}/stick_band/tension'] = np.asarray(tension)
        for label, effects in (('loop', None), ('loop_coulomb', {'pivot_coulomb_friction': 0.01})):
            q = p.replace(force_sensor_enabled=False)
            sim = InstrumentSim(q, obj='needle', effects=effects, seed=3)
            ctrl = GripController(q)
            inputs = ctrl.new_inputs()
            rows = []
            for k in range(LOOP_STEPS):
                t = k * 1e-3
                master = 0.6 * max(0.0, 1.0 - t / 0.2)
                sample, o = closed_loop_step(sim, ctrl, inputs, t, master, 1e-3)
                truth = sim.truth()
                rows.append((o.current_command, o.estimated_force, o.feedforward_current,
                             truth['grip_force'], sample.jaw_angle, sample.motor_angle))
            out[f'{name}/{label}'] = np.array(rows)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--config-dir', type=Path, default=Path('config'))
    parser.add_argument('--out', type=Path, required=True)
    args = parser.parse_args()
    np.savez_compressed(args.out, **compute(args.config_dir))


if __name__ == '__main__':
    main()
