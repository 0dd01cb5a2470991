"""The laryngoscope in pymunk: the space of ``n`` devices that the single device (:mod:`.single`) and the
pymunk batch (:mod:`.batch`) step; their state and its readings are engine-neutral (:mod:`.state`).

* **Blade**: a dynamic body, one convex shape. **Hand**: a kinematic body at the grip, moved only by
  velocity (so the coupling's damper sees the motion). **Coupling**: :func:`virtual_coupling`.
  **Incisors**: a static rounded segment; pymunk solves that contact. Its force reported is
  ``|total_impulse| / h`` summed over the substeps of a control period and divided by the period; its
  force and torque on the blade (:func:`teeth_on_blade`) go into the next substep's tongue contact.
* In a batch, device ``i`` sits at its own place in the plane (a grid 1 m apart, so no shapes of two
  devices ever meet): positions there carry the offset, which changes their rounding, so device 0
  (at the origin) equals a single device bit for bit and the others agree to rounding (tested).

Reproducibility. No contact state crosses a control period: at the start of each, a device whose
blade touched the incisors during the last one has them removed and added again (dropping pymunk's
cached contact impulses) and its blade's position-correction velocity cleared, so a device rebuilt
from :meth:`~.state.LaryngoscopeBase.state` (pickle, deepcopy, reset) continues bit for bit.
"""

from __future__ import annotations

import math
from typing import Any, Callable

import numpy as np

try:
    import pymunk
    from pymunk._chipmunk import ffi as _ffi
    from pymunk._chipmunk import lib as _lib
except ImportError as exc:  # pragma: no cover - the device extra is part of every test install
    raise ImportError("the simulated laryngoscope needs pymunk >= 7: pip install 'softenv[device]'") from exc

from .params import INCISOR_RADIUS, SHAPE_FRICTION, SPRING_LENGTH, LaryngoscopeParams
from .physics import teeth_force
from .state import COLLISION_SLOP, SOLVER_ITERATIONS

BLADE_TYPE, INCISOR_TYPE = 1, 2
GRID_SPACING = 1.0            # m between devices in a batch


def virtual_coupling(hand: pymunk.Body, body: pymunk.Body, anchor: tuple[float, float],
                     p: LaryngoscopeParams) -> tuple[pymunk.Constraint, ...]:
    """The hand -> blade coupling: two 1 m ``DampedSpring`` s along the hand's axes meeting at
    ``anchor`` (body frame) and a ``DampedRotarySpring`` (see the module docstring)."""
    k, c = p.coupling_stiffness, p.coupling_damping
    return (pymunk.DampedSpring(hand, body, (-SPRING_LENGTH, 0.0), anchor, SPRING_LENGTH, k, c),
            pymunk.DampedSpring(hand, body, (0.0, SPRING_LENGTH), anchor, SPRING_LENGTH, k, c),
            pymunk.DampedRotarySpring(hand, body, 0.0, p.rotational_stiffness, p.rotational_damping))



def teeth_on_blade(arbiter: Any, blade: Any, h: float) -> tuple[float, float, float]:
    """The incisors' force and torque on ``blade`` (a ``cpBody *``) in the substep of ``h`` s that
    ``arbiter`` (a ``cpArbiter *``, after its solve) was solved in: :func:`~.physics.teeth_force` on
    Chipmunk's own contact records (pymunk's ``Arbiter`` shows only their sum)."""
    n, contacts = arbiter.n, arbiter.contacts
    # the solver applies rotate(n, (jn, jt)) to body b and its negative to body a
    if arbiter.body_b == blade:
        return teeth_force(n.x, n.y, [(contacts[i].r2.x, contacts[i].r2.y, contacts[i].jnAcc, contacts[i].jtAcc)
                                      for i in range(arbiter.count)], h)
    return teeth_force(-n.x, -n.y, [(contacts[i].r1.x, contacts[i].r1.y, contacts[i].jnAcc, contacts[i].jtAcc)
                                    for i in range(arbiter.count)], h)


def listen_to_incisors(space: pymunk.Space, on_contact: Callable[[Any], None]) -> Any:
    """Call ``on_contact(arbiter)`` with the ``cpArbiter *`` of every blade-incisor contact after each
    substep's solve; returns the callback, which must be kept alive as long as the space.

    pymunk's post-solve handler builds an ``Arbiter`` and looks up its data on every call (2.4 us, a
    third of a substep); a cffi callback straight on Chipmunk's handler costs 0.5 us. Where the platform
    refuses write+execute memory for cffi callbacks (hardened runtimes), pymunk's handler is used."""
    space.on_collision(BLADE_TYPE, INCISOR_TYPE,
                       post_solve=lambda arbiter, space, data: on_contact(arbiter._arbiter))
    try:
        callback = _ffi.callback("void(cpArbiter *, cpSpace *, cpDataPointer)",
                                 lambda arbiter, space, data: on_contact(arbiter))
    except (MemoryError, RuntimeError):        # pragma: no cover - platform dependent
        return None
    space._handlers[(BLADE_TYPE, INCISOR_TYPE)]._handler.postSolveFunc = callback
    return callback


class DeviceSpace:
    """The pymunk space of ``n`` devices (hands, blades, couplings, incisors) at their grid places."""

    def __init__(self, p: LaryngoscopeParams, n: int) -> None:
        # Chipmunk's "hasty" space on one thread: the same deterministic step, 10 % faster at 1,024
        # devices (an ordinary space where pymunk has none, on Windows)
        self.space = pymunk.Space(threaded=True)
        self.space.threads = 1
        self.space.collision_slop = COLLISION_SLOP
        self.space.iterations = SOLVER_ITERATIONS
        self.step = _lib.cpHastySpaceStep if self.space.threaded else _lib.cpSpaceStep
        side = math.ceil(math.sqrt(n))
        self.offsets = np.array([[GRID_SPACING * (i % side), GRID_SPACING * (i // side)] for i in range(n)])
        self.hands: list[pymunk.Body] = []
        self.blades: list[pymunk.Body] = []
        self.incisors: list[pymunk.Segment] = []
        for ox, oy in self.offsets.tolist():
            hand = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
            blade = pymunk.Body(p.mass, p.moment)
            # one shape a side, so one contact a device: with two, the solver's order of them would
            # depend on the spatial index's history, and a rebuilt device would not continue bit for bit
            shape = pymunk.Poly(blade, p.outline)
            shape.collision_type, shape.friction, shape.elasticity = BLADE_TYPE, SHAPE_FRICTION, 0.0
            (ax, ay), (bx, by) = p.incisor_segment
            incisor = pymunk.Segment(self.space.static_body, (ox + ax, oy + ay), (ox + bx, oy + by), INCISOR_RADIUS)
            incisor.collision_type, incisor.friction, incisor.elasticity = INCISOR_TYPE, SHAPE_FRICTION, 0.0
            self.space.add(hand, blade, shape, incisor, *virtual_coupling(hand, blade, p.grip, p))
            self.hands.append(hand)
            self.blades.append(blade)
            self.incisors.append(incisor)
        self._incisor_shapes = [shape._shape for shape in self.incisors]      # the C handles flush uses
        self._blade_bodies = [body._body for body in self.blades]

    def place(self, i: int, blade_pose: tuple[float, float, float], blade_velocity: tuple[float, float, float],
              hand_pose: tuple[float, float, float]) -> None:
        """Put device ``i`` at local poses (x, y, angle) and velocities, dropping its contact state."""
        ox, oy = self.offsets[i].tolist()
        blade, hand = self.blades[i], self.hands[i]
        blade.position = (ox + blade_pose[0], oy + blade_pose[1])
        blade.angle = blade_pose[2]
        blade.velocity = blade_velocity[:2]
        blade.angular_velocity = blade_velocity[2]
        hand.position = (ox + hand_pose[0], oy + hand_pose[1])
        hand.angle = hand_pose[2]
        hand.velocity = (0.0, 0.0)
        hand.angular_velocity = 0.0
        self.flush(i)

    def flush(self, *devices: int) -> None:
        """Drop the contact state of these devices that their poses and velocities do not show: pymunk's
        cached contact impulses (remove and add their incisors again) and the blades'
        position-correction velocities, which Chipmunk's solver leaves for the next step's position
        update (a position update over zero time applies nothing and clears them)."""
        # through the C API: pymunk's Python bookkeeping stays valid (the same shape goes straight back)
        space, remove, add, update = self.space._space, _lib.cpSpaceRemoveShape, _lib.cpSpaceAddShape, \
            _lib.cpBodyUpdatePosition
        for i in devices:
            remove(space, self._incisor_shapes[i])
            add(space, self._incisor_shapes[i])
            update(self._blade_bodies[i], 0.0)
