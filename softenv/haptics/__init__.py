"""Everything between softenv and a person's hand at the servo rate.

* :mod:`.loop` -- :class:`HapticLoop`: the laryngoscope and tongue ticked at 1 kHz for a force-feedback
  device's driver (pose in, force out; the tongue's surface at the graphics rate).
* :mod:`.arms` -- vendor arms (a 3D Systems Touch, a Force Dimension device) with their 1 kHz servo loops.
* :mod:`.bridge` -- the UDP protocol a driver process in any language speaks to a ``softenv play`` session.
* The device presets (a Touch's, a Falcon's, an omega's limits) and their force rule are
  :mod:`softenv.devices.haptic_presets`: the laryngoscope renders its force through them, and devices sit
  below this package. They are re-exported here.

A session turns the arms and the bridge into actions in :mod:`softenv.training.inputs`; their speed is
measured by ``softenv bench`` (``bench/haptic.py``, ``bench/bridge.py``, beside every other measurement).
"""

from __future__ import annotations

import importlib
from typing import Any

from ..devices.haptic_presets import PRESETS, HapticPreset, render_force


def __getattr__(name: str) -> Any:
    # the loop runs the pymunk device (the device extra): the bridge and the presets must not pull it in
    if name == "HapticLoop":
        return importlib.import_module(".loop", __name__).HapticLoop
    raise AttributeError(f"module 'softenv.haptics' has no attribute {name!r}")


__all__ = ["PRESETS", "HapticLoop", "HapticPreset", "render_force"]
