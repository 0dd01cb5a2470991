"""What drives the hand in a ``softenv play`` session: an input device turns a person's input into the
next action of SoftSphereHaptic-v0 and feels the force the device renders back.

Every backend meets :class:`InputDevice`: ``handle`` sees the window's events, ``action`` gives the
action for the next control period, ``feel`` takes the force rendered to the hand after it, ``close``
lets the hardware go. Rate devices (keys, a mouse drag, a gamepad's sticks) give the hand's velocity
as the action; pose devices (the network bridge, a haptic arm) give where the hand should be, and the
session steers toward it with :func:`softenv.training.hand.action_toward`, so a log of their session
replays exactly as it was played.

Backends: :class:`PygameInput` (keyboard, mouse, gamepad; the default), :class:`BridgeInput` (a device
process speaking :mod:`softenv.haptics.bridge` over UDP), and :class:`ArmInput` (a vendor arm of
:mod:`softenv.haptics.arms`). The hardware and the wire live in :mod:`softenv.haptics`; this module
only turns them into a session's actions.
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np

from ..haptics.arms import ServoDevice
from ..haptics.bridge import BridgeServer
from .hand import action_toward, pose_after, relative_hand_pose

# every control of a session, as the screen and ``softenv play --help`` list them
CONTROLS: tuple[tuple[str, str], ...] = (
    ("Left / Right", "insert the blade / withdraw it"),
    ("Down / Up", "lift along the handle (press) / ease off"),
    ("A / D", "sweep the tongue left / right"),
    ("Q / E", "tip the blade up / down (wrist)"),
    ("Shift + key", "fine: a quarter of the speed"),
    ("mouse drag", "joystick: drag left inserts, down lifts"),
    ("gamepad", "sticks: insert, lift / sweep, tip"),
    ("Space / P", "start, pause and resume"),
    ("Esc", "end the session (the score follows)"),
)
RAMP_FLOOR = 0.2       # a key's first control period moves at this share of full speed ...
RAMP_S = 0.5           # ... rising to full speed over this long held
FINE = 0.25            # Shift scales the keys' rate by this
DRAG_FULL_PX = 60.0    # a mouse drag this long is full speed
DEAD_ZONE = 0.12       # gamepad stick travel ignored around the centre (sticks drift)
# action axis -> (key for +1, key for -1) in pygame's names
KEYS = (("K_LEFT", "K_RIGHT"), ("K_DOWN", "K_UP"), ("K_d", "K_a"), ("K_e", "K_q"))


@runtime_checkable
class InputDevice(Protocol):
    """A source of actions for a session (see the module docstring)."""

    name: str

    def handle(self, event: Any) -> None:
        """See one window event (keys, mouse, gamepad); devices with their own channel ignore them."""
        ...

    def action(self, env: Any, dt: float) -> np.ndarray:
        """The action ``(4,)`` float32 in [-1, 1] for the next control period of ``env``."""
        ...

    def feel(self, step: int, time_s: float, force_N: np.ndarray) -> None:
        """The force ``(3,)`` (world x, y, z; N) rendered to the hand after control period ``step``."""
        ...

    def close(self) -> None:
        """Let the device go."""
        ...

    def describe(self) -> str:
        """How a session's log names this device (with what it counted, where it counts)."""
        ...


class PygameInput:
    """Keyboard, mouse and gamepads through pygame's events (:data:`CONTROLS`).

    A key's rate ramps from :data:`RAMP_FLOOR` of full speed to full speed over :data:`RAMP_S` held
    (counted in control periods, so a scripted session is the same at any frame rate); Shift scales it
    by :data:`FINE`. A left-button mouse drag is a joystick (:data:`DRAG_FULL_PX` = full speed); gamepad
    sticks are read with a :data:`DEAD_ZONE`. Inputs add, then clip to [-1, 1] (:meth:`rates`); the hand
    then steers to the pose those rates reach (:func:`softenv.training.hand.pose_after`), so the session's
    log replays as it was played.
    """

    name = "keys, mouse and gamepad"

    def __init__(self, pygame: Any) -> None:
        self.pg = pygame
        self.down: set[int] = set()
        self.held_s = np.zeros(4)
        self.drag_from: tuple[int, int] | None = None
        self.mouse = (0, 0)
        pygame.joystick.init()
        self.pads = [pygame.joystick.Joystick(i) for i in range(pygame.joystick.get_count())]

    def handle(self, event: Any) -> None:
        pg = self.pg
        if event.type == pg.KEYDOWN:
            self.down.add(event.key)
        elif event.type == pg.KEYUP:
            self.down.discard(event.key)
        elif event.type == pg.MOUSEBUTTONDOWN and event.button == 1:
            self.drag_from = self.mouse = event.pos
        elif event.type == pg.MOUSEBUTTONUP and event.button == 1:
            self.drag_from = None
        elif event.type == pg.MOUSEMOTION:
            self.mouse = event.pos

    def action(self, env: Any, dt: float) -> np.ndarray:
        return action_toward(env, pose_after(env, self.rates(dt)))

    def rates(self, dt: float) -> np.ndarray:
        """The inputs' action for the next control period of ``dt`` s, before the walls (see the class)."""
        pg = self.pg
        keys = np.array([float(getattr(pg, plus) in self.down) - float(getattr(pg, minus) in self.down)
                         for plus, minus in KEYS])
        self.held_s = np.where(keys != 0.0, self.held_s + dt, 0.0)
        rate = RAMP_FLOOR + (1.0 - RAMP_FLOOR) * np.minimum(self.held_s / RAMP_S, 1.0)
        fine = FINE if self.down & {pg.K_LSHIFT, pg.K_RSHIFT} else 1.0
        a = keys * rate * fine
        if self.drag_from is not None:
            a[0] += (self.drag_from[0] - self.mouse[0]) / DRAG_FULL_PX
            a[1] += (self.mouse[1] - self.drag_from[1]) / DRAG_FULL_PX
        for pad in self.pads:
            axes = np.array([pad.get_axis(j) if j < pad.get_numaxes() else 0.0 for j in range(4)])
            axes = np.sign(axes) * np.clip((np.abs(axes) - DEAD_ZONE) / (1.0 - DEAD_ZONE), 0.0, 1.0)
            a += axes * (-1.0, 1.0, 1.0, 1.0)
        return np.clip(a, -1.0, 1.0)

    def feel(self, step: int, time_s: float, force_N: np.ndarray) -> None:
        """Keys and sticks render no force: the gauges show it."""

    def close(self) -> None:
        self.pg.joystick.quit()

    def describe(self) -> str:
        return "keys"


class BridgeInput:
    """A device process on the network bridge (:mod:`softenv.haptics.bridge`): the hand moves toward
    the newest pose it sent (held where it was until one comes) and the rendered force goes back with
    the sequence number of that pose. ``wait_s``: how long each period waits for a pose (0 in real time;
    a second for a device in lockstep with a session that runs as fast as it can)."""

    name = "a device over the bridge"

    def __init__(self, server: BridgeServer, wait_s: float = 0.0) -> None:
        self.server, self.wait_s = server, wait_s
        self.goal: np.ndarray | None = None
        self.seq = 0

    def handle(self, event: Any) -> None:
        """The device speaks over UDP, not through the window."""

    def action(self, env: Any, dt: float) -> np.ndarray:
        if self.goal is None:
            self.goal = relative_hand_pose(env)
        sent = self.server.poll(self.wait_s)
        if sent is not None:
            self.goal, self.seq = sent.pose, sent.seq
        return action_toward(env, self.goal)

    def feel(self, step: int, time_s: float, force_N: np.ndarray) -> None:
        self.server.send_force(self.seq, time_s, force_N)

    def close(self) -> None:
        """The server belongs to its opener (``softenv play`` closes it)."""

    def describe(self) -> str:
        return "a device over the bridge, messages " + ", ".join(f"{k} {v}" for k, v in self.server.counts.items())


class ArmInput:
    """A vendor haptic arm (:mod:`softenv.haptics.arms`): the hand moves toward the stylus's newest pose and
    the rendered force goes back through the arm's servo loop."""

    def __init__(self, arm: ServoDevice) -> None:
        self.arm = arm
        self.name = arm.name

    def handle(self, event: Any) -> None:
        """The arm has its own channel, not the window's events."""

    def action(self, env: Any, dt: float) -> np.ndarray:
        return action_toward(env, self.arm.hand_pose())

    def feel(self, step: int, time_s: float, force_N: np.ndarray) -> None:
        self.arm.feel(force_N)

    def close(self) -> None:
        self.arm.close()

    def describe(self) -> str:
        return self.arm.describe()
