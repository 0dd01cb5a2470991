"""Devices: what turns an agent's action into a force on the tissue. The env composes one, chosen by
the scene's ``device.kind``, through the contract of :mod:`softenv.devices.base`.

* :mod:`softenv.devices.base` -- the contract (one device on floats, a batch on arrays) and the kinds.
* :mod:`softenv.devices.ideal` -- the ideal device: the action is the force (no dynamics).
* :mod:`softenv.devices.laryngoscope` -- a laryngoscope blade in pymunk, held through a hand by a
  virtual coupling, pressing the tongue and levering on the upper incisors (its physics imports pymunk).
* :mod:`softenv.devices.contact` -- the blade-tongue contact law, consistent with the tissue.
* :mod:`softenv.devices.haptic_presets` -- force-feedback device presets (what a person would feel).

Nothing here imports pymunk until a scene names the laryngoscope.
"""
