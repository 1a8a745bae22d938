"""The hydraulic family: cylinder-driven manipulators (excavator, wheel loader, knuckle-boom
crane) as machine files, solved by one numpy core (paper 000; docs/hydraulic_family.md)."""

from manipulator_kinematics.hydraulic.description import Description, parse, read
from manipulator_kinematics.hydraulic.model import HydraulicModel, HydraulicState, StrokeError

__all__ = ["Description", "HydraulicModel", "HydraulicState", "StrokeError", "parse", "read"]
