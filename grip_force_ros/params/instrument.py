"""Instrument parameters: geometry, materials, motor, and hardware limits.

Defaults are the paper's Table 1 (``config/paper_needle_driver.yaml`` repeats
them with their sources), converted once to SI. Where the paper is silent
(cable radius, limits) the default is our stated assumption.
"""
import math

from grip_force_ros.params.schema import ParamSpec

_P = ParamSpec

INSTRUMENT = [
    _P('instrument_name', 'string', 'paper_needle_driver', '',
       'Human-readable instrument identifier; appears in logs and /diagnostics.',
       read_only=True),
    _P('torque_constant', 'double', 1.44, 'N*m/A',
       'Motor torque constant K (paper Table 1: 1.44 N*m/A). Motor torque M0 = K*I.',
       min=1e-4, max=20.0, read_only=True),
    _P('gear_ratio', 'double', 1.23, '',
       'Reduction between motor and cable drum (paper: 1.23). Drum torque = gear_ratio*K*I.',
       min=0.01, max=1000.0, read_only=True),
    _P('drum_radius', 'double', 0.004, 'm',
       'Cable drum radius r0 (Table 1: 4 mm).', min=1e-4, max=0.05, read_only=True),
    _P('guide_pulley_radii', 'double_array', (0.003, 0.003, 0.003), 'm',
       'Radii R of the guide pulleys between drum and jaw, in order from the drum (Table 1: 3, 3, 3 mm).',
       min=1e-4, max=0.05, read_only=True),
    _P('guide_pulley_wrap_angles', 'double_array', (math.pi / 2, math.pi / 4, math.pi / 4), 'rad',
       'Cable wrap angle on each guide pulley, same order (Table 1: pi/2, pi/4, pi/4).',
       min=0.0, max=2 * math.pi, read_only=True),
    _P('wrist_wrap_gain', 'double', 0.0, 'rad/rad',
       'Extra wrap on the last guide pulley per rad of |wrist pitch| (cables of the jaw pass over the '
       'wrist axis). The paper reports a minimal wrist effect and gives no value: default 0.',
       min=0.0, max=2.0, read_only=True),
    _P('wrist_cable_wrap_angles', 'double_array', (math.pi / 4,), 'rad',
       'Wrap angles of the wrist cable on its guide pulleys (paper: one pulley to the wrist).',
       min=0.0, max=2 * math.pi, read_only=True),
    _P('drive_pulley_radius', 'double', 0.0025, 'm',
       'Jaw (end effector) drive pulley radius r_n (Table 1: r4 = 2.5 mm).',
       min=1e-4, max=0.05, read_only=True),
    _P('drive_resistance_fraction', 'double', 0.5, '',
       "Static part of the resistance moment M' at the jaw drive pulley, as a fraction of the "
       "ideal drive torque r_n*F0: M = r_n*F0*(lambda_n - fraction). The paper prints "
       "M' = (2 r_n M0 - ...)/(2 r0) = r_n*F0 (fraction 1, which makes M < 0 for any lambda_n < 1); "
       'we read the leading 2 as a typo: 0.5 (default). 0 = no static resistance. See docs/model.md.',
       min=0.0, max=1.0, read_only=True),
    _P('wrist_finger_coupling', 'double', 0.6, 'rad/rad',
       'Jaw rotation induced per rad of wrist pitch (paper: 3/5).', min=-2.0, max=2.0, read_only=True),
    _P('jaw_moment_arm_tip', 'double', 0.012, 'm',
       'Distance l from the jaw pivot to the contact point (Table 1: l1 = 12 mm); needle and rigid contact.',
       min=1e-4, max=0.1, read_only=True),
    _P('jaw_moment_arm_inner', 'double', 0.0095, 'm',
       'Inner end l\' of a distributed tissue contact (Table 1: l2 = 9.5 mm); tissue force acts at '
       '(l+l\')/2.',
       min=1e-4, max=0.1, read_only=True),
    _P('cable_modulus', 'double', 1.25e11, 'Pa',
       'Elastic modulus E of the cable (Table 1: 1.25e5 MPa).', min=1e8, max=5e11, read_only=True),
    _P('cable_radius', 'double', 0.0002, 'm',
       'Cable radius r. NOT in the paper: assumed 0.2 mm (a 0.4 mm steel cable, usual in 8 mm '
       'instruments). Sets the friction exponents via rho = (R - r)/r and the section A = pi r^2.',
       min=1e-5, max=0.005, read_only=True),
    _P('cable_yield_strength', 'double', 1.08e9, 'Pa',
       'Largest tension per nominal cable section (tension / (pi r^2)) the cable takes; the '
       'drum tension at max_current must stay below it (grip-force params --check and node '
       'start refuse the instrument otherwise). Default: stainless steel (CRES) 7x19 wire rope, '
       'MIL-W-83420 Comp B, 1/16 in: 480 lbf minimum breaking strength (FAA AC 43.13-1B, '
       'Table 7-3) = 2135 N on pi (0.794 mm)^2 = 1.08 GPa (3/32 in: 0.92, 1/8 in: 0.99 GPa). '
       'Rope tables give breaking, not yield, strength; a rope yields below it, so an '
       'instrument above this value cannot be built, one below it may still need a margin.',
       min=1e7, max=1e10, read_only=True),
    _P('pulley_friction_coefficient', 'double', 0.15, '',
       'Cable-pulley friction coefficient mu (Table 1: 0.15).', min=0.0, max=1.0, read_only=True),
    _P('tension_friction_gain', 'double', 0.0, '1/N',
       'Tension-dependent friction: mu(F) = mu*(1 + gain*F). 0 = the paper\'s constant-mu model.',
       min=0.0, max=1.0, read_only=True),
    _P('needle_friction_coefficient', 'double', 0.15, '',
       "Jaw-needle friction coefficient mu' (Table 1: 0.15, stainless steel).", min=0.0, max=1.0,
       read_only=True),
    _P('needle_diameter', 'double', 0.0005, 'm',
       'Suture needle diameter (paper: 0.5 mm).', min=1e-5, max=0.005, read_only=True),
    _P('drum_mass', 'double', 0.0025, 'kg', 'Drum mass m0 (Table 1: 2.5 g).',
       min=0.0, max=1.0, read_only=True),
    _P('jaw_mass', 'double', 0.001, 'kg', 'End effector (jaw) mass m_n (Table 1: m4 = 1 g).',
       min=0.0, max=1.0, read_only=True),
    # --- friction, spring and load loss at the jaw (model/jaw_friction.py); all 0: off -------------
    _P('jaw_coulomb_friction', 'double', 0.0, 'N*m',
       'Coulomb friction C0 at the jaw at jaw_spring_rest_angle: the chain torque the jaw loses '
       'while the drive slides closing and keeps while it slides opening (friction state s, '
       'jaw_friction_width). 0 = off (the paper gives none). A da Vinci Maryland forceps: '
       '75 mN*m (docs/real_data.md).',
       min=0.0, max=1.0, read_only=True),
    _P('jaw_coulomb_friction_slope', 'double', 0.0, 'N*m/rad',
       'Change C1 of the Coulomb friction per rad of jaw opening about jaw_spring_rest_angle '
       '(friction along the stroke: C = max(C0 + C1 (phi - phi_r), 0)). 0 = constant.',
       min=-1.0, max=1.0, read_only=True),
    _P('jaw_friction_width', 'double', 0.02, 'rad',
       'Dahl width of the friction state over the drive (drum) angle: each displacement dx moves '
       's toward sign(dx) by 1 - exp(-|dx|/width), so the friction reverses over a few widths '
       'and sticks without motion. Used only when a jaw friction term is nonzero. Default: the '
       'rig estimator\'s 0.02 rad (docs/real_data.md).',
       min=1e-6, max=1.0, read_only=True),
    _P('jaw_spring_torque', 'double', 0.0, 'N*m',
       'Position spring moment K0 at jaw_spring_rest_angle, opening positive (it takes chain '
       'torque from the grip): K = K0 + k1 (phi - phi_r) + k2 (phi - phi_r)^2. 0 = off.',
       min=-1.0, max=1.0, read_only=True),
    _P('jaw_spring_slope', 'double', 0.0, 'N*m/rad',
       'Linear term k1 of the position spring per rad of jaw opening (negative: restoring, the '
       'spring closes an opened jaw). 0 = off.',
       min=-10.0, max=10.0, read_only=True),
    _P('jaw_spring_curvature', 'double', 0.0, 'N*m/rad^2',
       'Quadratic term k2 of the position spring. 0 = off.',
       min=-10.0, max=10.0, read_only=True),
    _P('jaw_spring_rest_angle', 'double', 0.0, 'rad',
       'Jaw angle phi_r about which the position spring and the friction along the stroke are '
       'expanded.',
       min=-math.pi, max=math.pi, read_only=True),
    _P('jaw_viscous_friction', 'double', 0.0, 'N*m*s/rad',
       "Viscous friction d at the jaw on its closing rate (torque d * (-jaw velocity) taken from "
       'the grip). 0 = off.',
       min=0.0, max=1.0, read_only=True),
    _P('jaw_efficiency_load_gain', 'double', 0.0, '1/(N*m)',
       'Load-dependent efficiency q: a friction q * tau^2 on the held torque tau, in the '
       'direction of the friction state, so the efficiency of each direction (the chain\'s, '
       'pulley_friction_coefficient through the stick band) falls as the load grows. 0 = off.',
       min=0.0, max=100.0, read_only=True),
    # --- the dVRK's jaw effort <-> current conversion (model/dvrk_jaw.py, docs/dvrk.md) ---------
    _P('dvrk_jaw_coupling', 'double', 1.2177, 'rad/rad',
       "Jaw coupling c of the dVRK tool file: the jaw row's last entry of "
       'coupling.ActuatorToJointPosition (jaw angle per rad of a jaw disk). The dVRK turns a jaw '
       'effort E into c*E N*m on each jaw actuator. Default: the Classic large needle driver '
       '(LARGE_NEEDLE_DRIVER_400006.json: 1.2177).',
       min=0.05, max=10.0, read_only=True),
    _P('dvrk_actuator_nm_to_amps', 'double', 1.949705, 'A/(N*m)',
       "NmToAmps of the PSM's jaw actuators in the dVRK's IO configuration (motor current per "
       'actuator torque, 1/(K_t*gear)). Default: the Classic PSM, 1/(0.0438 N*m/A * 11.71) = '
       '1.949705 (sawIntuitiveResearchKit @ 95a7e92, share/jhu-dVRK/sawRobotIO1394-PSM1-28007.xml).',
       min=0.01, max=100.0, read_only=True),
    # --- the dVRK's jaw position loop (model/dvrk_jaw.py JawPositionLoop, docs/dvrk.md) -------
    _P('dvrk_disc_p_gain', 'double', 6.0, 'N*m/rad',
       "Proportional gain of the PSM's tool-disc PIDs (per disc, actuator space): the jaw's "
       'stiffness in position mode is p / (2 c^2). Default: sawIntuitiveResearchKit '
       'share/pid/sawControllersPID-PSM.json, disc_1..disc_4 p_gain 6.0.',
       min=1e-3, max=1000.0, read_only=True),
    _P('dvrk_disc_d_gain', 'double', 0.09, 'N*m*s/rad',
       "Derivative gain of the PSM's tool-disc PIDs (per disc): the jaw's damping in position "
       'mode is d / (2 c^2). Default: share/pid/sawControllersPID-PSM.json, d_gain 0.09.',
       min=0.0, max=100.0, read_only=True),
    _P('dvrk_actuator_max_current', 'double', 0.670, 'A',
       "The drive's current limit of one jaw disc motor (sawRobotIO1394 MaxCurrent). Default: "
       'the Classic PSM, 0.670 A (share/jhu-dVRK/sawRobotIO1394-PSM1-28007.xml, actuators 3..6).',
       min=1e-3, max=20.0, read_only=True),
]

LIMITS = [
    _P('max_current', 'double', 0.5, 'A',
       'Hardware current limit. The paper sweeps 0..0.5 A.', min=0.0, max=20.0,
       read_only=True, group='limits'),
    _P('max_current_slew', 'double', 100.0, 'A/s',
       'Hardware limit on the rate of change of the current command.', min=0.0, max=1e5,
       read_only=True, group='limits'),
    _P('max_grip_force', 'double', 12.0, 'N',
       'Largest grip force the controller may ever target.', min=0.0, max=200.0,
       read_only=True, group='limits'),
    _P('jaw_angle_min', 'double', -0.1, 'rad',
       'Smallest plausible measured jaw angle (0 = closed); below it the input is rejected.',
       min=-math.pi, max=math.pi, read_only=True, group='limits'),
    _P('jaw_angle_max', 'double', math.pi / 2 + 0.1, 'rad',
       'Largest plausible measured jaw angle: the mechanical open stop (pi/2; the sim: '
       'jaw_open_stop) plus a 0.1 rad margin for encoder noise, as jaw_angle_min sits 0.1 rad '
       'below the closed stop.',
       min=-math.pi, max=math.pi, read_only=True, group='limits'),
    _P('wrist_angle_limit', 'double', math.pi / 2, 'rad',
       'Largest plausible |wrist pitch|; beyond it the input is rejected.', min=0.0, max=math.pi,
       read_only=True, group='limits'),
    _P('dvrk_jaw_effort_max', 'double', 0.16, 'N*m',
       "The tool's jaw effort limit (dVRK tool file jaw.ftmax). In the dvrk interface the "
       'controller never commands more (its current limit becomes min(max_current, the current '
       'of this effort)) and the simulated PSM refuses a larger jaw/servo_jf. Default: the Classic '
       'large needle driver (LARGE_NEEDLE_DRIVER_400006.json: 0.16).',
       min=0.0, max=5.0, read_only=True, group='limits'),
]
