"""Vendor haptic arms: a 3D Systems Touch through OpenHaptics (``pyOpenHaptics``, the ``touch`` extra) and a Force Dimension
omega, sigma or delta through its SDK (``forcedimension-core``, the ``forcedimension`` extra).

Both run a 1 kHz servo loop beside the session, as CHAI3D's and SOFA's device plugins do: OpenHaptics
calls our servo callback from its own scheduler thread; for Force Dimension a thread of ours reads the
position and writes the force every millisecond. Each servo tick stores the stylus position and renders
the newest force; a ``softenv play`` session (50 Hz, through :class:`softenv.training.inputs.ArmInput`)
reads the newest position mapped into the hand's workspace, steers the hand there, then hands back the
force the laryngoscope renders. What runs without hardware is tested with a simulated SDK (``tests/test_haptic_devices.py``);
the vendor calls themselves are untested here, for want of the devices.

Axes: the servo loop works in OpenHaptics' frame (x right, y up, z toward the user; Force Dimension's x
toward the user, y right, z up is turned into it and back). Pushing the stylus away from you
inserts the blade (hand x falls with z), lowering it presses the tongue (hand z is y), moving it right
sweeps right (hand y is x). The stylus position at the
start of the session is the hand's start pose; ``scale`` maps device metres to hand metres. These are
3-DOF position devices here: the wrist (pitch) stays level. Forces go back through the same axes,
times ``force_scale``, saturated at ``max_force_N`` (the Touch renders about 3.3 N, an omega.3 12 N).
"""

from __future__ import annotations

import threading
import time
from typing import Any

import numpy as np

SERVO_HZ = 1000.0


class ServoDevice:
    """What the vendor backends share: the newest stylus position (written by the servo loop) and the newest
    force to render (written by the session), behind a lock; the mapping between the two frames."""

    name = "a haptic arm"

    def __init__(self, workspace: tuple[np.ndarray, np.ndarray], scale: float = 1.0, force_scale: float = 0.25,
                 max_force_N: float = 3.0) -> None:
        for value, name in ((scale, "scale"), (force_scale, "force_scale"), (max_force_N, "max_force_N")):
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name}={value!r} must be a finite number > 0")
        self.low, self.high = (np.asarray(w, dtype=np.float64) for w in workspace)
        self.scale, self.force_scale, self.max_force_N = scale, force_scale, max_force_N
        self._lock = threading.Lock()
        self._origin: np.ndarray | None = None
        self._position = np.zeros(3)
        self._force = np.zeros(3)
        self.ticks = 0

    def servo_tick(self, position_m: Any) -> np.ndarray:
        """One tick of the servo loop: store the stylus position (m; x right, y up, z toward the user); returns
        the force (N, same axes) to render now."""
        p = np.asarray(position_m, dtype=np.float64)
        with self._lock:
            if self._origin is None:
                self._origin = p.copy()
            self._position = p
            self.ticks += 1
            return self._force.copy()

    def hand_pose(self) -> np.ndarray:
        """The newest stylus position as a hand pose relative to the start (x, z, pitch, y), in the workspace."""
        with self._lock:
            moved = np.zeros(3) if self._origin is None else self._position - self._origin
        x, y, z = moved * self.scale
        return np.clip(np.array([z, y, 0.0, x]), self.low, self.high)

    def feel(self, force_N: np.ndarray) -> None:
        """Render ``force_N`` (N, world x, y, z) from the next servo tick on, scaled and saturated."""
        fx, fy, fz = np.asarray(force_N, dtype=np.float64) * self.force_scale
        force = np.array([fy, fz, fx])                                    # world (x, y, z) -> device axes
        size = float(np.linalg.norm(force))
        if size > self.max_force_N:
            force *= self.max_force_N / size
        with self._lock:
            self._force = force

    def close(self) -> None:
        """Stop the servo loop and release the arm (the backends)."""

    def describe(self) -> str:
        return f"{self.name}, {self.ticks} servo ticks"


class TouchDevice(ServoDevice):
    """A 3D Systems Touch (or Touch X) through OpenHaptics' scheduler: ``pip install 'softenv[touch]'`` and
    OpenHaptics with the Touch drivers. Positions arrive in mm and forces leave in N."""

    name = "3D Systems Touch (OpenHaptics)"

    def __init__(self, workspace: tuple[np.ndarray, np.ndarray], **mapping: Any) -> None:
        super().__init__(workspace, **mapping)
        try:                                            # OpenHaptics' libHD loads when these are imported
            from pyOpenHaptics import hd                # the touch extra
            from pyOpenHaptics.hd_callback import hd_callback  # the touch extra
            from pyOpenHaptics.hd_device import HapticDevice   # the touch extra
        except (ImportError, OSError) as exc:
            raise ValueError(f"a Touch needs pyOpenHaptics and OpenHaptics ({exc}): pip install 'softenv[touch]' and "
                             "install OpenHaptics with the Touch drivers") from None

        @hd_callback
        def servo() -> None:                            # OpenHaptics' servo thread, at 1 kHz
            transform = hd.get_transform()
            force = self.servo_tick([transform[3][0] * 1e-3, transform[3][1] * 1e-3, transform[3][2] * 1e-3])
            hd.set_force([float(f) for f in force])

        self._servo = servo                             # keep the C callback alive while the scheduler holds it
        self._device = HapticDevice(callback=servo, scheduler_type="async")

    def close(self) -> None:
        self._device.close()


class ForceDimensionDevice(ServoDevice):
    """A Force Dimension omega, sigma or delta (or a Novint Falcon) through the Force Dimension SDK:
    ``pip install 'softenv[forcedimension]'`` and the SDK's drivers. A thread of ours is the servo loop."""

    name = "Force Dimension (dhd)"

    def __init__(self, workspace: tuple[np.ndarray, np.ndarray], **mapping: Any) -> None:
        super().__init__(workspace, **mapping)
        try:
            from forcedimension_core import dhd         # the forcedimension extra
        except (ImportError, OSError) as exc:
            raise ValueError(f"a Force Dimension device needs forcedimension-core ({exc}): pip install "
                             "'softenv[forcedimension]' and install the Force Dimension SDK") from None
        if dhd.open() < 0:
            raise ValueError(f"no Force Dimension device opened: {dhd.errorGetLastStr()}")
        dhd.enableForce(True)
        self._dhd = dhd
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._servo_loop, name="softenv-forcedimension-servo", daemon=True)
        self._thread.start()

    def _servo_loop(self) -> None:
        dhd, position, period = self._dhd, [0.0, 0.0, 0.0], 1.0 / SERVO_HZ
        next_tick = time.perf_counter()
        while not self._stop.is_set():                  # the SDK's axes: x toward the user, y right, z up
            dhd.getPosition(out=position)
            right, up, toward = self.servo_tick([position[1], position[2], position[0]])
            dhd.setForce([float(toward), float(right), float(up)])
            next_tick += period
            time.sleep(max(0.0, next_tick - time.perf_counter()))

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=1.0)
        self._dhd.setForce([0.0, 0.0, 0.0])
        self._dhd.close()


BACKENDS: dict[str, type[ServoDevice]] = {"touch": TouchDevice, "forcedimension": ForceDimensionDevice}
