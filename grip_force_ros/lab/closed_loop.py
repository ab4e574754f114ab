"""One period of the closed loop without middleware: sim sample in, control step, command out.

The ROS nodes close this loop over topics (``sim_instrument`` publishes its sample, the
``controller`` takes it into its inputs, steps and publishes the current command, the sim
applies it for one period). Figures, benchmarks and tests that need the same loop offline
call :func:`closed_loop_step` once per period::

    sim = InstrumentSim(params, obj='needle', seed=3)
    ctrl = GripController(params)
    inputs = ctrl.new_inputs()
    for k in range(1000):
        t = k * 1e-3
        sample, out = closed_loop_step(sim, ctrl, inputs, t, traj.angle(t), 1e-3)

A lost or stale input is a source left out of ``sources`` for that period: the controller
keeps the last value it received and its watchdogs see the age grow, as in the nodes.

Plain objects in and out, no rclpy: the sim is an
:class:`~grip_force_ros.sim.plant.InstrumentSim`, the controller a
:class:`~grip_force_ros.control.GripController` and its
:class:`~grip_force_ros.control.inputs.ControlInputs`.
"""
from __future__ import annotations

import math

from grip_force_ros.control.inputs import SOURCES

#: Every input the controller takes (``control.inputs.SOURCES``): the master's gripper
#: angle, the instrument's wrist and jaw, the actuator's current and drum, the force sensor.
ALL_SOURCES = frozenset(SOURCES)
#: Every input but the force sensor (a sensorless instrument's loop).
NO_FORCE_SENSOR = ALL_SOURCES - {'force'}
#: No input at all (a blackout of every stream).
NO_SOURCES = frozenset()


def closed_loop_step(sim, controller, inputs, t: float, master_angle: float, period: float, *,
                     sources: frozenset = ALL_SOURCES, stamped: bool = False):
    """Run one period: the sim's sample into the inputs, one control step, the command on.

    Parameters
    ----------
    sim : InstrumentSim
        The simulated instrument; sampled now, then stepped by ``period`` under the command.
    controller : GripController
        The controller; stepped once at ``t``.
    inputs : ControlInputs
        The controller's inputs (``controller.new_inputs()``); updated from the sample for
        every source in ``sources``, the others keep their last value and age.
    t : float
        Time of this period (s); the receive time of every input updated.
    master_angle : float
        Master gripper opening angle (rad); used only when ``'master'`` is in ``sources``.
    period : float
        Time to the next period (s): how long the sim applies the command.
    sources : frozenset of str
        The inputs that arrive this period, from :data:`ALL_SOURCES`.
    stamped : bool
        Give every input the source stamp ``t`` (s) as well, as the nodes' messages carry;
        without it the inputs have no stamp (NaN) and only their receive time counts.

    Returns
    -------
    sample : SimMeasurement
        The sim's sample the controller used (taken before the sim stepped).
    output : ControlOutput
        The controller's output for this period (``output.current_command``, A, went to the sim).

    Raises
    ------
    ValueError
        A name in ``sources`` that is not one of :data:`ALL_SOURCES` (a typo would otherwise
        read as a lost input).
    """
    unknown = set(sources) - ALL_SOURCES
    if unknown:
        raise ValueError(f'unknown input sources {sorted(unknown)}; known: {sorted(ALL_SOURCES)}')
    stamp = t if stamped else math.nan
    sample = sim.measure()
    if 'master' in sources:
        inputs.set_master(t, master_angle, stamp)
    if 'instrument' in sources:
        inputs.set_instrument(t, sample.wrist_angle, sample.jaw_angle, sample.jaw_velocity, stamp)
    if 'actuator' in sources:
        inputs.set_actuator(t, sample.current, sample.motor_angle, sample.motor_velocity, stamp)
    if 'force' in sources:
        inputs.set_force(t, sample.grip_force, stamp)
    output = controller.step(t, inputs)
    sim.step(output.current_command, period)
    return sample, output
