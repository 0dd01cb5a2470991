"""The laryngoscope's arithmetic, written once against ``ops`` (Python floats or numpy arrays).

* **Virtual coupling** hand -> blade (Colgate, Stanley & Brown 1995). Translation: two pymunk
  ``DampedSpring`` s along the hand's axes, each 1 m long at rest. A zero-length spring would damp
  only along the momentary separation, so its transverse motion would ring undamped; two long
  orthogonal springs give the stiffness ``k`` in every direction (to second order in the
  separation over 1 m) and pymunk's implicit damping along both axes. Rotation: a
  ``DampedRotarySpring``. pymunk integrates them (:mod:`.space`); :func:`coupling_force` reads
  their pull from the state.
* **Tongue contact** (computed outside pymunk, applied each substep: :func:`tongue_substep`): the
  point of the blade's underside nearest the sphere's centre penetrates by ``delta``; the normal
  force follows :class:`~softenv.devices.contact.TongueContact`, applied along the sphere's normal.
* **Jaw** (where the airway has lower incisors: :func:`jaw_force`): a frictionless, critically damped
  spring pushing the underside up where it presses the lower incisal edge, computed outside pymunk and
  applied each substep with the tongue's force.
* **Lateral sweep**: the blade's lateral position ``y`` is a mass on a spring-damper to the hand's
  lateral position (the same ``k`` and ``c`` as the coupling), and the tongue holds it by the
  stick-slip law of :class:`TongueContact`: coupled to the sagittal motion through the normal force
  (the friction limit ``mu P``; no contact, no drag). Integrated as pymunk integrates its springs
  (explicit springs, implicit damping, symplectic Euler).

pymunk applies a spring's damping implicitly but after its explicit spring impulse (a first-order
split): the period and decay of a damped oscillation err by about ``0.5 zeta omega h``. The default
damping ratios (0.14 translational, 0.11 rotational) keep that under 1 % (tested against the
analytic damped oscillator); heavier damping is stable but less accurate at the same substep.

The batch (:mod:`.batch`) runs these functions with :class:`~softenv._ops.ArrayOps` on arrays; the
single device (:mod:`.single`) runs them with :class:`~softenv._ops.ScalarOps` on Python floats, and
for its hot substep :func:`tongue_substep_floats`, :func:`tongue_substep` written out for floats
(tested bit for bit against it). The same IEEE operations in the same order, so both get the same bits.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from math import sqrt
from typing import Any, cast

from ..._ops import PhysicsOps, ScalarOps
from ..contact import TongueContact
from .params import INCISOR_RADIUS, JAW_STIFFNESS, LaryngoscopeParams

CONTACT_DAMPING_RATIO = 1.0    # the tongue contact: critically damped (tissue is viscous)
NO_TEETH = (0.0, 0.0, 0.0)     # the incisors' force and torque on a blade clear of them


@dataclass
class Constants:
    """Per-scene numbers the substep arithmetic reads (attributes: fast in the scalar path)."""

    R: float
    h: float
    inv_m: float
    inv_I: float
    h_over_m: float
    k: float
    c: float
    k_t: float
    mu: float
    k_ref: float
    damping: float
    step: float
    inv_step: float
    top: int
    k_rot: float
    c_rot: float
    grip: tuple[float, float]
    heel: tuple[float, float]
    tip: tuple[float, float]
    low: tuple[float, ...]
    high: tuple[float, ...]
    jaw: tuple[float, float] | None = None   # the lower incisal edge's centre; None: no lower incisors
    jaw_radius: float = 0.0
    k_jaw: float = 0.0
    c_jaw: float = 0.0



def substep_constants(p: LaryngoscopeParams, contact: TongueContact, h: float) -> Constants:
    m_eff = p.effective_mass(p.reach())
    k_explicit = p.explicit_contact_stiffness(contact)
    damping = min(2.0 * CONTACT_DAMPING_RATIO * math.sqrt(k_explicit * m_eff), m_eff / h)
    low, high = p.hand_box
    jaw_damping = min(2.0 * CONTACT_DAMPING_RATIO * math.sqrt(JAW_STIFFNESS * m_eff), m_eff / h)
    return Constants(R=p.radius, h=h, inv_m=1.0 / p.mass, inv_I=1.0 / p.moment, h_over_m=h / p.mass,
                      k=p.coupling_stiffness, c=p.coupling_damping, k_t=contact.lateral_stiffness, mu=p.friction,
                      k_ref=k_explicit, damping=damping, step=contact.step, inv_step=contact.inv_step,
                      top=contact.top, k_rot=p.rotational_stiffness, c_rot=p.rotational_damping, grip=p.grip,
                      heel=p.heel, tip=p.tip, low=low, high=high, jaw=p.jaw, jaw_radius=INCISOR_RADIUS,
                      k_jaw=JAW_STIFFNESS if p.jaw is not None else 0.0, c_jaw=jaw_damping if p.jaw is not None else 0.0)



def nearest_point(px: Any, py: Any, cos_a: Any, sin_a: Any, c: Constants, ops: PhysicsOps) -> tuple[Any, Any, Any]:
    """The point of the blade's underside (heel to tip) nearest the tongue's centre, and its distance."""
    hx, hy = c.heel
    tx, ty = c.tip
    ex = px + cos_a * hx - sin_a * hy
    ey = py + sin_a * hx + cos_a * hy
    dx = (px + cos_a * tx - sin_a * ty) - ex
    dy = (py + sin_a * tx + cos_a * ty) - ey
    t = ops.clip(-(ex * dx + ey * dy) / (dx * dx + dy * dy), 0.0, 1.0)
    cx = ex + t * dx
    cy = ey + t * dy
    return cx, cy, ops.sqrt(cx * cx + cy * cy) + 1e-300


def jaw_contact(px: Any, py: Any, cos_a: Any, sin_a: Any, c: Constants) -> tuple[Any, Any, Any, Any]:
    """Where the underside meets the lower incisal edge (``c.jaw`` must be set): the edge's depth into
    the underside (along its normal; positive: pressing), whether it presses (the depth positive and the
    point over the edge's centre between heel and tip), and that point relative to the blade's centre
    ``(rx, ry)``."""
    hx, hy = c.heel
    tx, ty = c.tip
    jx, jy = cast(tuple[float, float], c.jaw)
    ex = px + cos_a * hx - sin_a * hy
    ey = py + sin_a * hx + cos_a * hy
    dx = (px + cos_a * tx - sin_a * ty) - ex
    dy = (py + sin_a * tx + cos_a * ty) - ey
    t = ((jx - ex) * dx + (jy - ey) * dy) / (dx * dx + dy * dy)
    depth = c.jaw_radius - ((ex - jx) * -sin_a + (ey - jy) * cos_a)
    return depth, (depth > 0.0) & (t >= 0.0) & (t <= 1.0), (ex + t * dx) - px, (ey + t * dy) - py


def jaw_force(blade: tuple, c: Constants, ops: PhysicsOps) -> tuple[Any, Any, Any]:
    """The jaw's push on the blade ``(x, y)`` and its torque, for ``blade`` as :func:`tongue_substep`
    reads it (``c.jaw`` must be set). Where the lower incisal edge's rounding (centre ``c.jaw``, radius
    ``c.jaw_radius``) presses the underside between heel and tip (:func:`jaw_contact`), a frictionless
    spring of ``c.k_jaw`` with the damper ``c.c_jaw`` pushes the underside up (along its normal) at the
    point over the edge's centre; nothing pulls. Explicit, like the tongue's reference stiffness:
    :meth:`~.params.LaryngoscopeParams.omega_max` counts it. Every engine writes the same operations (the
    Warp and Triton kernels, the single device on floats with ``ScalarOps``)."""
    px, py, a, cos_a, sin_a, vx, vy, w = blade
    depth, pressed, rx, ry = jaw_contact(px, py, cos_a, sin_a, c)
    ux, uy = -sin_a, cos_a                                     # the underside's normal, into the blade
    approach = -((vx - w * ry) * ux + (vy + w * rx) * uy)     # speed of that point into the jaw
    F = ops.positive(c.k_jaw * depth + c.c_jaw * approach) * pressed
    fx = F * ux
    fy = F * uy
    return fx, fy, rx * fy - ry * fx


def tongue_substep(blade: tuple, hand: tuple, lateral: tuple, hl: Any, teeth: tuple, loads: Any, slopes: Any,
                   c: Constants, ops: PhysicsOps) -> tuple[Any, ...]:
    """One substep of the tongue's contact: the arithmetic both devices share (the batch runs it on
    arrays; the single device runs :func:`tongue_substep_floats`, this function written out for floats).

    ``blade`` is ``(x, y, angle, cos, sin, vx, vy, spin)``, ``hand`` is ``(x, y, pitch, vx, vy, spin)``,
    ``lateral`` is ``(blade y, blade vy, hand y, anchor)`` with the hand's ``y`` already moved this
    substep at its velocity ``hl``, ``teeth`` the incisors' force and torque on the blade in the last
    substep (:func:`teeth_force`; zeros without that contact), plus the jaw's in this one where there is
    a jaw (:func:`jaw_force`). Returns ``(fx, fy, torque, P, Q, cx, cy,
    lat_y, lat_v, anchor)``: the tongue's push on the blade and its torque, the normal and sideways force,
    the contact point, and the lateral state after the substep.

    **Normal force**, at the blade's point ``(cx, cy)`` nearest the tongue's centre. The law's
    stiffness up to ``K_ref`` is explicit; the excess ``K_ex`` (the steepest slope between here and
    where this substep's approach speed would take the blade), with a critical damper
    ``c_ex = 2 sqrt(K_ex m)`` so that the stiff barrier does not ring, is applied by backward Euler
    along the normal, with the blade's effective mass ``m`` there and the push of the other forces on
    the blade predicted: the coupling's from the current state, the incisors' from the last substep
    and the jaw's (a blade levered on the teeth is pushed by both; predicting the coupling's alone left a levered
    press 9-13 % under the law). With ``s = K_ex h + c_ex``,
    ``P (1 + s h / m) = P(delta) + (c + s) v + s h a``, where ``v`` is the approach speed and ``a`` the
    acceleration those forces give that point into the tongue. At rest ``a = P / m``, so a held press
    settles exactly on the law, however stiff it is there, levered on the teeth or not; the prediction
    leaves out the tongue's own last force, so it does not feed energy back.

    **Lateral**: the blade's lateral mass between the hand's spring-damper and the tongue's
    stick-slip grip, as pymunk integrates its springs: explicit springs, implicit damping, then the
    position (symplectic Euler; stable for ``omega h < 2``, which the substep keeps below 0.3).
    """
    px, py, a, cos_a, sin_a, vx, vy, w = blade
    lat_y, lat_v, hand_lat, anchor = lateral
    cx, cy, dist = nearest_point(px, py, cos_a, sin_a, c, ops)
    touching = dist < c.R
    if ops is ScalarOps and not touching:       # off the tongue P is 0: the single device skips its arithmetic
        fx = fy = torque = P = 0.0
    else:
        depth = c.R - dist
        nx = cx / dist
        ny = cy / dist
        rx = cx - px
        ry = cy - py
        approach = -((vx - w * ry) * nx + (vy + w * rx) * ny)     # speed of that point into the tongue
        rn = rx * ny - ry * nx
        inv_meff = c.inv_m + rn * rn * c.inv_I
        i = ops.index(ops.positive(depth) * c.inv_step, c.top)
        slope = ops.take(slopes, i)
        law = ops.take(loads, i) + (depth - i * c.step) * slope
        ahead = ops.take(slopes, ops.index(ops.positive(depth + c.h * approach) * c.inv_step, c.top))
        slope = ops.where(ahead > slope, ahead, slope)
        excess = ops.positive(slope - c.k_ref)
        # the excess spring, critically damped, both implicit: K_ex h + c_ex, with c_ex = 2 sqrt(K_ex m)
        stiff = excess * c.h + 2.0 * ops.sqrt(excess / inv_meff)
        # the acceleration of the contact point into the tongue by the coupling (this instant) and the
        # incisors (the last substep); where stiff = 0 it is multiplied by 0
        Fx, Fy, tau = coupling_force(blade, hand, c)
        Tx, Ty, Tt = teeth
        push = -((Fx + Tx) * nx + (Fy + Ty) * ny) * c.inv_m - (tau + Tt) * rn * c.inv_I
        beta = stiff * c.h * inv_meff
        P = ops.positive((law + (c.damping + stiff) * approach + stiff * c.h * push) / (1.0 + beta)) * touching
        fx = P * nx
        fy = P * ny
        torque = rx * fy - ry * fx
    k_s = c.k_t * touching
    lat_v = (lat_v + c.h_over_m * (c.k * (hand_lat - lat_y) + c.c * hl - k_s * (lat_y - anchor))) / \
        (1.0 + c.h_over_m * c.c)
    lat_y = lat_y + c.h * lat_v
    stuck = k_s * (lat_y - anchor)
    limit = c.mu * P
    Q = ops.clip(stuck, -limit, limit)                         # Coulomb: past mu P the anchor slides
    anchor = ops.where(touching, ops.where(Q != stuck, lat_y - Q / c.k_t, anchor), lat_y)
    return fx, fy, torque, P, Q, cx, cy, lat_y, lat_v, anchor


def tongue_substep_floats(blade: tuple, hand: tuple, lateral: tuple, hl: float, teeth: tuple[float, float, float],
                          loads: list[float], slopes: list[float], c: Constants) -> tuple[float, ...]:
    """:func:`tongue_substep` on Python floats with ``ScalarOps``, written out: the same operations in the
    same order, with the ops and the helpers (:func:`nearest_point`, :func:`coupling_force`) inlined.
    The single device runs it every substep (a third of the step's time went to those calls);
    ``tests/test_laryngoscope.py`` holds it to :func:`tongue_substep` bit for bit."""
    px, py, a, cos_a, sin_a, vx, vy, w = blade
    lat_y, lat_v, hand_lat, anchor = lateral
    hx, hy = c.heel
    tx, ty = c.tip
    ex = px + cos_a * hx - sin_a * hy
    ey = py + sin_a * hx + cos_a * hy
    dx = (px + cos_a * tx - sin_a * ty) - ex
    dy = (py + sin_a * tx + cos_a * ty) - ey
    t = -(ex * dx + ey * dy) / (dx * dx + dy * dy)
    t = 0.0 if t < 0.0 else (1.0 if t > 1.0 else t)
    cx = ex + t * dx
    cy = ey + t * dy
    dist = sqrt(cx * cx + cy * cy) + 1e-300
    touching = dist < c.R
    if not touching:                            # off the tongue P is 0
        fx = fy = torque = P = 0.0
    else:
        depth = c.R - dist
        nx = cx / dist
        ny = cy / dist
        rx = cx - px
        ry = cy - py
        approach = -((vx - w * ry) * nx + (vy + w * rx) * ny)
        rn = rx * ny - ry * nx
        inv_meff = c.inv_m + rn * rn * c.inv_I
        top = c.top
        x = (depth if depth > 0.0 else 0.0) * c.inv_step
        i = int(x) if x < top else top
        slope = slopes[i]
        law = loads[i] + (depth - i * c.step) * slope
        x = depth + c.h * approach
        x = (x if x > 0.0 else 0.0) * c.inv_step
        ahead = slopes[int(x) if x < top else top]
        slope = ahead if ahead > slope else slope
        excess = slope - c.k_ref
        excess = excess if excess > 0.0 else 0.0
        stiff = excess * c.h + 2.0 * sqrt(excess / inv_meff)
        gx, gy, pitch, hvx, hvy, hw = hand
        (qa, qb) = c.grip
        qx, qy = cos_a * qa - sin_a * qb, sin_a * qa + cos_a * qb
        Fx = c.k * (gx - px - qx) + c.c * (hvx - vx + w * qy)
        Fy = c.k * (gy - py - qy) + c.c * (hvy - vy - w * qx)
        tau = qx * Fy - qy * Fx + c.k_rot * (pitch - a) + c.c_rot * (hw - w)
        Tx, Ty, Tt = teeth
        push = -((Fx + Tx) * nx + (Fy + Ty) * ny) * c.inv_m - (tau + Tt) * rn * c.inv_I
        beta = stiff * c.h * inv_meff
        P = (law + (c.damping + stiff) * approach + stiff * c.h * push) / (1.0 + beta)
        P = P if P > 0.0 else 0.0
        fx = P * nx
        fy = P * ny
        torque = rx * fy - ry * fx
    k_s = c.k_t * touching
    lat_v = (lat_v + c.h_over_m * (c.k * (hand_lat - lat_y) + c.c * hl - k_s * (lat_y - anchor))) / \
        (1.0 + c.h_over_m * c.c)
    lat_y = lat_y + c.h * lat_v
    stuck = k_s * (lat_y - anchor)
    limit = c.mu * P
    Q = -limit if stuck < -limit else (limit if stuck > limit else stuck)
    anchor = ((lat_y - Q / c.k_t) if Q != stuck else anchor) if touching else lat_y
    return fx, fy, torque, P, Q, cx, cy, lat_y, lat_v, anchor


def teeth_force(nx: float, ny: float, contacts: list[tuple[float, float, float, float]],
                h: float) -> tuple[float, float, float]:
    """The incisors' force ``(x, y)`` and torque on the blade over a substep of ``h`` s, from Chipmunk's
    arbiter: its normal ``(nx, ny)`` (into the blade) and, for each contact, the offset ``(rx, ry)`` from
    the blade's centre and the accumulated normal and tangent impulses ``(jn, jt)`` (all that the solver
    applied this substep: its cached impulse at ``dt_coef = 1`` plus its iterations'). The Warp and
    Triton kernels write the same sum out."""
    tx = ty = tq = 0.0
    for rx, ry, jn, jt in contacts:
        jx, jy = nx * jn - ny * jt, nx * jt + ny * jn
        tx, ty, tq = tx + jx, ty + jy, tq + (rx * jy - ry * jx)
    return tx / h, ty / h, tq / h


def grip_offset(cos_a: Any, sin_a: Any, c: Constants) -> tuple[Any, Any]:
    """The grip's offset (m) from the blade's centre of mass, in the world frame."""
    return cos_a * c.grip[0] - sin_a * c.grip[1], sin_a * c.grip[0] + cos_a * c.grip[1]


def coupling_force(blade: tuple, hand: tuple, c: Constants) -> tuple[Any, Any, Any]:
    """The coupling's force ``(Fx, Fy)`` and torque on the blade now: the hand's springs at the grip
    and the wrist spring, each with its damper (the hand feels the opposite)."""
    px, py, a, cos_a, sin_a, vx, vy, w = blade
    gx, gy, pitch, hvx, hvy, hw = hand
    qx, qy = grip_offset(cos_a, sin_a, c)
    Fx = c.k * (gx - px - qx) + c.c * (hvx - vx + w * qy)
    Fy = c.k * (gy - py - qy) + c.c * (hvy - vy - w * qx)
    return Fx, Fy, qx * Fy - qy * Fx + c.k_rot * (pitch - a) + c.c_rot * (hw - w)


def near_walls(pose: tuple[float, ...], velocity: tuple[float, ...], low: tuple[float, ...],
                high: tuple[float, ...], period: float) -> list[bool]:
    """For each axis of a hand at ``pose`` moving at ``velocity`` for ``period`` s: whether it comes
    within 1e-6 (m or rad) of its box. Where it does not, every substep's wall clip returns the
    velocity unchanged: the clip's bounds ``(low - x) / h`` and ``(high - x) / h`` are ~1e-6 / h away
    from it, and the rounding of ``x`` is ~1e-17."""
    return [min(x, x + v * period) < lo + 1e-6 or max(x, x + v * period) > hi - 1e-6
            for x, v, lo, hi in zip(pose, velocity, low, high)]


def hand_command(action: Any, pitch: Any, p: LaryngoscopeParams, ops: PhysicsOps) -> tuple[Any, Any, Any, Any]:
    """World velocities ``(vX, vY, spin, v_lateral)`` of the hand for normalised actions, in the hand's
    frame at the start of the control period: insert along the blade toward its tip, press along the
    blade's normal into the tongue, sweep toward +y, pitch counter-clockwise (tip down)."""
    cos_a, sin_a = ops.cos(pitch), ops.sin(pitch)
    v = p.max_hand_speed
    return (v * (-action[0] * cos_a + action[1] * sin_a), v * (-action[0] * sin_a - action[1] * cos_a),
            p.max_pitch_rate * action[3], p.max_sweep_speed * action[2])


def hand_action(vX: float, vY: float, spin: float, v_lateral: float, pitch: float,
                p: LaryngoscopeParams) -> tuple[float, float, float, float]:
    """The action whose :func:`hand_command` at hand pitch ``pitch`` is the world velocity ``(vX, vY,
    spin, v_lateral)`` (its exact inverse; not clipped to ``[-1, 1]``)."""
    cos_a, sin_a = math.cos(pitch), math.sin(pitch)
    v = p.max_hand_speed
    return (-(vX * cos_a + vY * sin_a) / v, (vX * sin_a - vY * cos_a) / v, v_lateral / p.max_sweep_speed,
            spin / p.max_pitch_rate)


def contact_features(cx: Any, cy: Any, anchor: Any, P: Any, Q: Any, R: float, ops: PhysicsOps) -> tuple[Any, Any, Any, Any]:
    """Force features of the contact: insertion and lateral arc (m), normal and sideways force (N)."""
    return R * ops.atan2(cy, cx), R * ops.asin(ops.clip(anchor / R, -1.0, 1.0)), P, Q


def squash(x: Any) -> Any:
    """``x / (1 + |x|)``: bounded in (-1, 1), slope 1 at 0, exact arithmetic (no ``tanh``: numpy's and
    the C library's differ in the last bit)."""
    return x / (1.0 + abs(x))

