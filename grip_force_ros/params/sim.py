"""Simulated-instrument parameters (groups 'sim' and 'effects'). Owned by sim/.

The 'sim' group describes the plant that stands in for hardware: what the
paper does not give (cable free length, motor inertia, damping, contact
stiffness, sensor noise) is our stated assumption. ``friction_scale`` and
``stiffness_scale`` make the plant differ from the instrument YAML on purpose
(the controller is not told).

The 'effects' group holds one strength per unmodelled effect the sim can generate,
named as in docs/design.md (every strength defaults to 0 = off), and the effects' further
parameters: all declared in the effect registry, :mod:`grip_force_ros.effects`.
"""
import math

from grip_force_ros.effects import REGISTRY, SIMULATED
from grip_force_ros.objects import OBJECTS
from grip_force_ros.params.schema import ParamSpec


def _sim(*args, **kwargs):
    return ParamSpec(*args, group='sim', **kwargs)


def _fx(*args, **kwargs):
    return ParamSpec(*args, group='effects', **kwargs)


SIM = [
    _sim('sim_rate', 'double', 10000.0, 'Hz',
         'Internal integration rate of the plant; step(dt) is split into sub-steps of at most '
         '1/sim_rate.', min=1000.0, max=200000.0),
    _sim('publish_rate', 'double', 1000.0, 'Hz',
         'Rate at which the simulated instrument node steps and publishes its sensors '
         '(dvrk profile: 100 Hz by default, the dVRK\'s ROS rate).',
         min=1.0, max=10000.0),
    _sim('state_message', 'string', 'combined', '',
         "crtk profile: how the instrument's state goes out each period. 'combined': one "
         'instrument/measured_js with wrist_pitch, jaw and jaw_drum (position, velocity; the '
         "drum's effort = measured current, A; the joints' effort NaN, not measured), as a "
         "drive's one frame carries its joints and its actuator; 'split': the joints on "
         'instrument/measured_js and the drum on instrument/actuator/measured_js. The '
         'controller steps on either (the combined message, or the actuator state).',
         choices=('combined', 'split'), read_only=True),
    _sim('command_timeout', 'double', 0.03, 's',
         'Drive-side command timeout: with no current command (crtk) or jaw effort (dvrk) for '
         'this long, the drive sets the current to 0 A and reports it (/diagnostics, a log '
         "warning), as a real drive does when its master stops talking (the dVRK's: 30 ms). "
         'Armed by the first command; the next command re-arms it.', min=0.001, max=10.0),
    _sim('homing_time', 'double', 0.5, 's',
         'dvrk profile: how long the simulated arm stays busy homing (state_command "home") '
         'before it reports is_homed.', min=0.0, max=60.0),
    _sim('cable_length', 'double', 0.09, 'm',
         'Effective free length L of the jaw cable (stiffness k = E*A/L). Assumed: 90 mm makes the '
         "elastic jaw-angle loss ~1 rad/A, the paper's creep term (1.046 rad/A).",
         min=1e-3, max=2.0),
    _sim('cable_jaw_side_fraction', 'double', 0.2, '',
         'Share of the cable length between the guide pulleys and the jaw (the rest runs from the '
         'drum to the pulleys). Splits the cable into two springs around the pulley friction.',
         min=0.01, max=0.99),
    _sim('stiffness_scale', 'double', 1.0, '',
         'Plant cable stiffness = YAML value (E*A/L) times this. 1 = the plant matches the YAML.',
         min=0.05, max=20.0),
    _sim('friction_scale', 'double', 1.0, '',
         'Plant cable-pulley friction coefficient = YAML mu times this. 1 = the plant matches the YAML.',
         min=0.0, max=5.0),
    _sim('motor_inertia', 'double', 1.0e-5, 'kg*m^2',
         'Motor rotor (and gear) inertia reflected to the drum, added to the drum inertia '
         '0.5*m0*r0^2. Not in the paper; assumed: a flat brushless motor of this torque class.',
         min=0.0, max=1e-2),
    _sim('jaw_inertia', 'double', 4.8e-8, 'kg*m^2',
         'Jaw inertia about its pivot. Default: a 1 g jaw (Table 1) as a 12 mm rod, m*l^2/3.',
         min=1e-12, max=1e-3),
    _sim('drum_damping', 'double', 6.0e-3, 'N*m*s/rad',
         'Viscous damping on the drum (motor drive, bearings, cable internal damping seen at the '
         'drum). Assumed: damping ratio ~0.5 of the drum-cable mode at the defaults (the paper only '
         'says the cable oscillation dies out within 0.1 s).', min=0.0, max=1.0),
    _sim('jaw_damping', 'double', 1.0e-5, 'N*m*s/rad',
         'Viscous damping at the jaw pivot that is part of the nominal plant (small).',
         min=0.0, max=1.0),
    _sim('current_loop_time_constant', 'double', 2.0e-4, 's',
         'First-order lag of the motor current loop: actual current follows the command with this '
         'time constant.', min=0.0, max=0.1),
    _sim('needle_stiffness', 'double', 2.0e5, 'N/m',
         'Contact stiffness of jaw + 0.5 mm needle, at the contact point (l from the pivot).',
         min=1.0, max=1e8),
    _sim('tissue_stiffness', 'double', 2.0e3, 'N/m',
         'Tissue contact stiffness at small compression (at the mean contact arm (l+l\')/2).',
         min=1.0, max=1e8),
    _sim('tissue_model', 'string', 'exponential', '',
         "Tissue force law: 'linear' F = k*d, or 'exponential' F = (k/b)*(exp(b*d) - 1) "
         '(soft tissue stiffens with compression d).', choices=('linear', 'exponential')),
    _sim('tissue_exponential_rate', 'double', 500.0, '1/m',
         "Rate b of the exponential tissue law (stiffness grows by e per 1/b of compression).",
         min=0.0, max=1e5),
    _sim('rigid_stiffness', 'double', 1.0e6, 'N/m',
         'Contact stiffness of a rigid object (and of the jaw hard stops), at the contact point.',
         min=1.0, max=1e9),
    _sim('contact_damping_ratio', 'double', 0.3, '',
         'Damping of every contact, as a ratio of critical damping of the jaw on that contact.',
         min=0.0, max=5.0),
    _sim('needle_contact_angle', 'double', 0.0417, 'rad',
         'Jaw angle at which the jaw touches the needle (0.5 mm at l = 12 mm: 0.5/12).',
         min=0.0, max=math.pi / 2),
    _sim('tissue_contact_angle', 'double', 0.25, 'rad',
         'Jaw angle at which the jaw touches the tissue (object position).', min=0.0, max=math.pi / 2),
    _sim('rigid_contact_angle', 'double', 0.1, 'rad',
         'Jaw angle at which the jaw touches the rigid object (object position).',
         min=0.0, max=math.pi / 2),
    _sim('jaw_open_stop', 'double', 0.0, 'rad',
         "Jaw angle of the simulated jaw's mechanical open stop (a hard stop, as the jaws "
         "touching at 0). 0: the instrument's jaw_angle_max less JAW_STOP_MARGIN (0.1 rad): "
         'pi/2 for the default instrument, 1.296 rad for the Maryland forceps (dVRK range '
         '80 deg). A value given must lie at least that margin below jaw_angle_max, the '
         'largest angle the controller takes as plausible.',
         min=0.0, max=math.pi),
    _sim('initial_jaw_angle', 'double', 0.6, 'rad',
         'Jaw angle at reset (no cable tension, motor angle 0).', min=0.0, max=math.pi / 2),
    _sim('initial_wrist_angle', 'double', 0.0, 'rad',
         'Wrist pitch at reset. The wrist is a kinematic input (set_wrist_angle).',
         min=-math.pi / 2, max=math.pi / 2),
    _sim('sim_object', 'string', 'needle', '',
         'Object between the jaws: free, rigid, tissue or needle.',
         choices=OBJECTS),
    _sim('current_noise_std', 'double', 0.002, 'A',
         'Std of white noise on the measured motor current.', min=0.0, max=1.0),
    _sim('motor_angle_noise_std', 'double', 1.0e-4, 'rad',
         'Std of white noise on the drum angle (encoder).', min=0.0, max=1.0),
    _sim('motor_velocity_noise_std', 'double', 0.01, 'rad/s',
         'Std of white noise on the drum velocity.', min=0.0, max=100.0),
    _sim('wrist_angle_noise_std', 'double', 1.0e-3, 'rad',
         'Std of white noise on the measured wrist angle.', min=0.0, max=1.0),
    _sim('jaw_angle_noise_std', 'double', 1.0e-3, 'rad',
         'Std of white noise on the measured jaw angle.', min=0.0, max=1.0),
    _sim('jaw_velocity_noise_std', 'double', 0.05, 'rad/s',
         'Std of white noise on the measured jaw velocity.', min=0.0, max=100.0),
    _sim('grip_force_noise_std', 'double', 0.02, 'N',
         'Std of white noise on the load-cell grip force.', min=0.0, max=10.0),
    _sim('sim_seed', 'integer', 0, '',
         'Seed of the sensor-noise generator of the simulated instrument.', min=0, max=2**31 - 1),
]


def _effect_specs() -> list:
    """Declare the 'effects' group from the effect registry.

    Each simulated effect's strength (default 0 = off), then its further parameters.
    """
    out = []
    for name in SIMULATED:
        e = REGISTRY[name]
        out.append(_fx(e.name, 'double', 0.0, e.unit, e.description, min=e.min, max=e.max))
        out += [_fx(x.name, 'double', x.default, x.unit, x.description, min=x.min, max=x.max)
                for x in e.params]
    return out


EFFECTS = _effect_specs()


#: Least distance (rad) from the simulated jaw's open stop to the instrument's jaw_angle_max:
#: the schema's defaults keep 0.1 rad (stop pi/2, plausible up to pi/2 + 0.1) for the
#: encoder noise and the stop's give under an opening current.
JAW_STOP_MARGIN = 0.1


def jaw_open_stop(values) -> float:
    """Return the simulated jaw's open stop (rad): ``jaw_open_stop``, or from ``jaw_angle_max`` if 0."""
    stop = values['jaw_open_stop']
    return stop if stop > 0.0 else values['jaw_angle_max'] - JAW_STOP_MARGIN


def check_sim(values) -> None:
    """Cross-parameter checks of the 'sim' group (called by ``check_consistency``).

    Raises
    ------
    ParameterError
        A command timeout shorter than two state periods (every command would time out);
        an open stop the controller would take as an implausible jaw angle (less than
        :data:`JAW_STOP_MARGIN` below ``jaw_angle_max``), or a reset jaw beyond that stop.
    """
    from grip_force_ros.params.schema import ParameterError
    stop, plausible = jaw_open_stop(values), values['jaw_angle_max']
    if stop + JAW_STOP_MARGIN > plausible + 1e-9:
        raise ParameterError(
            f"'jaw_open_stop' {stop} rad is less than {JAW_STOP_MARGIN} rad below "
            f"'jaw_angle_max' {plausible} rad: the simulated jaw would open to angles the "
            'controller rejects as implausible')
    if values['initial_jaw_angle'] > stop:
        raise ParameterError(f"'initial_jaw_angle' {values['initial_jaw_angle']} rad is beyond "
                             f"the open stop {stop} rad ('jaw_open_stop')")
    rate, timeout = values['publish_rate'], values['command_timeout']
    if timeout * rate < 2.0:
        raise ParameterError(
            f"'command_timeout' {timeout} s is less than two state periods at 'publish_rate' "
            f'{rate:g} Hz: the drive would cut every command')
