"""The simulated haptic loop: a device, a virtual coupling, an operator model, the engine at 1 kHz."""

from fixplan.haptics.coupling import VirtualCoupling, check_passivity
from fixplan.haptics.device import DeviceSpecs, HapticDevice, SimulatedDevice
from fixplan.haptics.loop import HapticLoop, LoopRecord

__all__ = [
    "DeviceSpecs",
    "HapticDevice",
    "HapticLoop",
    "LoopRecord",
    "SimulatedDevice",
    "VirtualCoupling",
    "check_passivity",
]
