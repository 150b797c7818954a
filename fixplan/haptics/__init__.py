"""The simulated haptic loop: a device, a virtual coupling, an operator model, the engine at 1 kHz."""

from fixplan.haptics.coordinates import coordinates_from_pose, pose_from_coordinates, workpiece_coordinates
from fixplan.haptics.coupling import VirtualCoupling, check_passivity
from fixplan.haptics.device import DeviceSpecs, HapticDevice, ReadDevice, SimulatedDevice
from fixplan.haptics.loop import HapticLoop, LoopRecord
from fixplan.haptics.rig import HapticRig, haptic_rig

__all__ = [
    "DeviceSpecs",
    "HapticDevice",
    "HapticLoop",
    "HapticRig",
    "LoopRecord",
    "ReadDevice",
    "SimulatedDevice",
    "VirtualCoupling",
    "check_passivity",
    "coordinates_from_pose",
    "haptic_rig",
    "pose_from_coordinates",
    "workpiece_coordinates",
]
