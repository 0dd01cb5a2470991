"""Devices: what turns an agent's action into a force on the tissue.

* :mod:`softenv.devices.ideal` -- the ideal device: the action is the force (no dynamics).
* :mod:`softenv.devices.laryngoscope` -- a laryngoscope blade in pymunk, held through a hand by a
  virtual coupling, pressing the tongue and levering on the upper incisors (imports pymunk).
* :mod:`softenv.devices.contact` -- the blade-tongue contact law, consistent with the tissue.
* :mod:`softenv.devices.presets` -- force-feedback device presets (what a person would feel).

This package's top level imports neither pymunk nor anything heavy: a scene without the
laryngoscope never loads it.
"""

# names of the laryngoscope's part of the observation (each value squashed into (-1, 1))
LARYNGOSCOPE_OBS = ("blade_x", "blade_z", "blade_pitch", "blade_y", "blade_vx", "blade_vz", "blade_spin", "blade_vy",
                    "hand_x", "hand_z", "hand_pitch", "hand_y", "tongue_normal", "tongue_sideways", "incisor")
IDEAL_OBS = ("insertion", "lateral", "normal", "sideways")
# scales of the laryngoscope's observation (value / scale, then squashed): here, not in the pymunk module,
# so that readers of the observation (softenv.control, the baselines) load without pymunk
POSITION_SCALE, ANGLE_SCALE, LATERAL_SCALE = 0.05, 0.5, 0.02             # m, rad, m
SPEED_SCALE, SPIN_SCALE, LATERAL_SPEED_SCALE = 0.2, 2.0, 0.1             # m/s, rad/s, m/s


def device_obs_names(kind: str) -> tuple[str, ...]:
    """Names of the device's part of the observation for a ``device.kind``."""
    return LARYNGOSCOPE_OBS if kind == "laryngoscope" else IDEAL_OBS
