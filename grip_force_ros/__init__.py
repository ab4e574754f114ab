"""grip_force_ros: grip-force model and force control of cable-driven surgical instruments."""

__version__ = '0.1.0'
