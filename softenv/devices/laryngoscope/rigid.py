"""The blade and the virtual coupling as Chipmunk steps them, written against ``ops`` (floats or arrays).

A first piece of the laryngoscope on arrays (issue 37): one ``cpSpaceStep`` of the blade (a dynamic
body) pulled by the hand (a kinematic body) through :func:`~.space.virtual_coupling`'s two
``DampedSpring`` s and its ``DampedRotarySpring``, under an external force and torque (the tongue's,
computed outside the space as today), in Chipmunk's order of operations:

1. positions from the velocities the bodies hold (symplectic Euler; the hand moves by its own);
2. each spring's explicit impulse (``preStep``: spring force times ``h``), from the new positions;
3. velocities from the external force and torque (no gravity, no space damping);
4. ``iterations`` passes of each spring's implicit damping impulse (``applyImpulse``), the springs in
   the order they were added.

With :class:`Incisors` (arrays), the blade's contact with the incisors joins in where Chipmunk
runs it (:mod:`.incisors`): the collision and the arbiters' pre-step after the positions, their cached
impulses after the velocities, their impulses before the springs' in each pass, and the bias velocity
of position correction spent at the next step's positions. Chipmunk's expressions are kept as written
(``n = delta * (1 / dist)``, the accumulated impulse clamped and differenced), so the same IEEE
operations run in the same order: :func:`coupling_step` equals pymunk bit for bit, clear of the teeth
and levered on them (``tests/test_laryngoscope_arrays.py``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ..._ops import PhysicsOps
from . import incisors
from .params import SPRING_LENGTH, LaryngoscopeParams


@dataclass(frozen=True)
class Coupling:
    """What one step of the coupled blade reads: the blade's inverse mass and moment, the grip (the
    springs' anchor on the blade, body frame), the springs' stiffness and damping."""

    m_inv: float
    i_inv: float
    grip: tuple[float, float]
    k: float
    c: float
    k_rot: float
    c_rot: float

    @classmethod
    def of(cls, p: LaryngoscopeParams) -> Coupling:
        return cls(1.0 / p.mass, 1.0 / p.moment, p.grip, p.coupling_stiffness, p.coupling_damping,
                   p.rotational_stiffness, p.rotational_damping)


# the hand-frame anchors of the two springs, in the order virtual_coupling adds them
HAND_ANCHORS = ((-SPRING_LENGTH, 0.0), (0.0, SPRING_LENGTH))


@dataclass
class Incisors:
    """The incisors' contact for a batch (arrays of the namespace ``xp``: numpy, or torch through
    ``array_api_compat``): the solver's constants, each device's arbiter, the blade's position-correction
    velocity (x, y, spin: Chipmunk's bias velocity, spent at the next step's position update) and the
    ratio of this step to the last (Chipmunk's ``dt_coef``: 0 at a space's first step, 1 after)."""

    solver: incisors.Solver
    arbiters: incisors.Arbiters
    bias: list[Any]
    xp: Any
    dt_coef: float = 1.0


def coupling_step(blade: tuple[Any, ...], hand: tuple[Any, ...], hand_v: tuple[Any, Any, Any],
                  force: tuple[Any, Any, Any], h: float, c: Coupling, iterations: int,
                  ops: PhysicsOps, teeth: Incisors | None = None) -> tuple[tuple[Any, ...], tuple[Any, ...]]:
    """One Chipmunk step of ``h`` seconds: ``blade`` (x, y, angle, vx, vy, spin), ``hand`` (x, y, pitch)
    moving at ``hand_v`` (vx, vy, spin), ``force`` (fx, fy, torque) on the blade's centre of mass, and
    with ``teeth`` (arrays only) the blade's contact with the incisors, whose state it updates.
    Returns the blade's and the hand's new state, as pymunk's ``space.step(h)`` leaves them."""
    px, py, a, vx, vy, w = blade
    gx, gy, pitch = hand
    hvx, hvy, hw = hand_v
    fx, fy, torque = force
    # 1. positions (cpBodyUpdatePosition), with the bias velocities the contact left, which it spends
    gx, gy, pitch = gx + hvx * h, gy + hvy * h, pitch + hw * h
    if teeth is None:
        px, py, a = px + vx * h, py + vy * h, a + w * h
    else:
        bvx, bvy, bw = teeth.bias
        px, py, a = px + (vx + bvx) * h, py + (vy + bvy) * h, a + (w + bw) * h
        teeth.bias = [teeth.xp.zeros_like(bvx), teeth.xp.zeros_like(bvy), teeth.xp.zeros_like(bw)]
    ca, sa, cp, sp = ops.cos(a), ops.sin(a), ops.cos(pitch), ops.sin(pitch)
    if teeth is not None:                       # collide, then the arbiters' pre-step before the springs'
        touching = incisors.prestep(teeth.arbiters, teeth.solver, px, py, ca, sa, teeth.xp)
        bounce = incisors.bounce_velocity(teeth.arbiters, vx, vy, w)
    qx, qy = c.grip
    r2x, r2y = ca * qx + -sa * qy, sa * qx + ca * qy
    # 2. the springs' explicit impulses (preStep); the hand is kinematic: impulses leave it as it is
    springs = []
    for ax, ay in HAND_ANCHORS:
        r1x, r1y = cp * ax + -sp * ay, sp * ax + cp * ay
        dx, dy = (px + r2x) - (gx + r1x), (py + r2y) - (gy + r1y)
        dist = ops.sqrt(dx * dx + dy * dy)
        inv = 1.0 / dist
        nx, ny = dx * inv, dy * inv
        rcn = r2x * ny - r2y * nx
        k = c.m_inv + c.i_inv * rcn * rcn
        n_mass = 1.0 / k
        v_coef = 1.0 - ops.exp(-c.c * h * k)
        j = (SPRING_LENGTH - dist) * c.k * h
        vx, vy = vx + nx * j * c.m_inv, vy + ny * j * c.m_inv
        w = w + c.i_inv * (r2x * (ny * j) - r2y * (nx * j))
        springs.append([r1x, r1y, nx, ny, n_mass, v_coef, 0.0, j])      # ..., target_vrn, jAcc
    i_sum = 1.0 / c.i_inv
    w_coef = 1.0 - ops.exp(-c.c_rot * h * c.i_inv)
    j_rot = ((pitch - a) - 0.0) * c.k_rot * h
    w = w + j_rot * c.i_inv
    target_wrn = 0.0
    # 3. velocities (cpBodyUpdateVelocity: the space's damping is 1, gravity 0)
    vx, vy = vx * 1.0 + (0.0 + fx * c.m_inv) * h, vy * 1.0 + (0.0 + fy * c.m_inv) * h
    w = w * 1.0 + torque * c.i_inv * h
    if teeth is not None:
        vx, vy, w = incisors.apply_cached(teeth.arbiters, touching, teeth.solver, teeth.dt_coef, vx, vy, w, teeth.xp)
    # 4. the implicit damping impulses (applyImpulse): the contact's, then the springs' in the order added
    for _ in range(iterations):
        if teeth is not None:
            vx, vy, w = incisors.apply_impulse(teeth.arbiters, touching, teeth.solver, bounce, vx, vy, w, teeth.bias,
                                               teeth.xp)
        for s in springs:
            r1x, r1y, nx, ny, n_mass, v_coef, target, acc = s
            rel_x = (vx + -r2y * w) - (hvx + -r1y * hw)
            rel_y = (vy + r2x * w) - (hvy + r1x * hw)
            vrn = rel_x * nx + rel_y * ny
            v_damp = (target - vrn) * v_coef
            s[6] = vrn + v_damp
            j = (acc + v_damp * n_mass) - acc       # the accumulated impulse clamped (to +-inf), differenced
            s[7] = acc + j
            vx, vy = vx + nx * j * c.m_inv, vy + ny * j * c.m_inv
            w = w + c.i_inv * (r2x * (ny * j) - r2y * (nx * j))
        wrn = hw - w
        w_damp = (target_wrn - wrn) * w_coef
        target_wrn = wrn + w_damp
        j = j_rot - (j_rot - w_damp * i_sum)
        j_rot = j_rot - j
        w = w - j * c.i_inv
    return (px, py, a, vx, vy, w), (gx, gy, pitch)
