"""The laryngoscope's pieces on arrays against pymunk itself. The blade and the virtual coupling
(softenv.devices.laryngoscope.rigid): a space holding only the hand, the blade and the coupling, stepped
with the same hand velocities and external forces, must leave the blade in the same state bit for bit,
step after step. The blade against the incisors (softenv.devices.laryngoscope.incisors): the same
contacts as Chipmunk's own collision (cpShapesCollide), bit for bit."""

from __future__ import annotations

import math

import numpy as np
import pymunk
import pytest
from pymunk._chipmunk import lib

from softenv._ops import ArrayOps, ScalarOps
from softenv.devices.laryngoscope.batch import LaryngoscopeArrays
from softenv.devices.laryngoscope.kernel import LaryngoscopeKernel
from softenv.devices.laryngoscope.incisors import Arbiters, Solver, collide, transformed
from softenv.devices.laryngoscope.params import INCISOR_RADIUS, SHAPE_FRICTION, LaryngoscopeParams
from softenv.devices.laryngoscope.part import laryngoscope_parts
from softenv.devices.laryngoscope.rigid import Coupling, Incisors, coupling_step
from softenv.devices.laryngoscope.single import Laryngoscope
from softenv.devices.laryngoscope.space import COLLISION_SLOP, SOLVER_ITERATIONS, virtual_coupling
from softenv.envs import HAPTIC_SCENES
from softenv.envs.config import scene_config
from softenv.envs.world import World
from softenv.training.hand import haptic_config

H = 1e-3                                        # the device's substep at the default scene


def pymunk_device(p: LaryngoscopeParams, threaded: bool, teeth: bool = False) -> tuple[pymunk.Space, pymunk.Body, pymunk.Body]:
    """The hand, the blade and the coupling in a space of their own; with ``teeth`` the incisors too, as
    the device space sets them (slop, friction)."""
    space = pymunk.Space(threaded=threaded)        # threaded: Chipmunk's hasty space, as the batch steps it
    if threaded:
        space.threads = 1
    space.iterations, space.collision_slop = SOLVER_ITERATIONS, COLLISION_SLOP
    hand, blade = pymunk.Body(body_type=pymunk.Body.KINEMATIC), pymunk.Body(p.mass, p.moment)
    hand.position, blade.position = p.grip_start, p.body_start
    shape = pymunk.Poly(blade, p.outline)
    shape.friction = SHAPE_FRICTION
    space.add(hand, blade, shape, *virtual_coupling(hand, blade, p.grip, p))
    if teeth:
        incisor = pymunk.Segment(space.static_body, *p.incisor_segment, INCISOR_RADIUS)
        incisor.friction = SHAPE_FRICTION
        space.add(incisor)
    return space, hand, blade


def pymunk_step(device: tuple[pymunk.Space, pymunk.Body, pymunk.Body], hand_v: np.ndarray, force: np.ndarray) -> list[float]:
    space, hand, blade = device
    hand.velocity, hand.angular_velocity = (float(hand_v[0]), float(hand_v[1])), float(hand_v[2])
    blade.force, blade.torque = (float(force[0]), float(force[1])), float(force[2])
    space.step(H)
    return [*blade.position, blade.angle, *blade.velocity, blade.angular_velocity]


@pytest.mark.parametrize("stiff, threaded", [(False, False), (True, True)])
def test_the_coupled_blade_steps_as_pymunk_steps_it_bit_for_bit(stiff, threaded):
    """Random hand velocities (0.1 m/s, 0.5 rad/s) and external forces (10 N, 0.3 N m: the tongue's
    scale) over 1,000 substeps, on Python floats and on arrays of 16 devices; the stiff case puts
    the coupling at 10 times its stiffness and damping, in Chipmunk's hasty space."""
    config = haptic_config(None)
    if stiff:
        config["device"] = {**config["device"], **{key: 10.0 * config["device"][key] for key in
                            ("coupling_stiffness", "coupling_damping", "rotational_stiffness", "rotational_damping")}}
    p = LaryngoscopeParams.from_config(config)
    c, n = Coupling.of(p), 16
    devices = [pymunk_device(p, threaded) for _ in range(n)]
    rng = np.random.default_rng(1)
    one = ((*p.body_start, 0.0, 0.0, 0.0, 0.0), (*p.grip_start, 0.0))
    many = tuple(tuple(np.full(n, v) for v in part) for part in one)
    for _ in range(1000):
        hand_v, force = rng.normal(0, [0.1, 0.1, 0.5], (n, 3)), rng.normal(0, [10.0, 10.0, 0.3], (n, 3))
        reference = np.array([pymunk_step(d, hand_v[i], force[i]) for i, d in enumerate(devices)])
        one = coupling_step(*one, tuple(hand_v[0].tolist()), tuple(force[0].tolist()), H, c, SOLVER_ITERATIONS, ScalarOps)
        many = coupling_step(*many, tuple(hand_v.T), tuple(force.T), H, c, SOLVER_ITERATIONS, ArrayOps)
        assert list(one[0]) == reference[0].tolist()
        assert np.array_equal(np.stack(many[0], axis=1), reference)
    assert np.ptp(reference[:, 0]) > 1e-3              # the devices went their own ways


def test_the_blade_meets_the_incisors_where_chipmunk_finds_it_bit_for_bit():
    """4,000 blade poses around the incisors (3 cm back and forth, 2 mm below to 30 mm into them,
    +-0.6 rad): the contact normal, the points on both surfaces and how many there are equal Chipmunk's own
    collision of the two shapes, where the cores stay apart (GJK's closest points) and where the blade sinks
    deeper than the incisors' 4 mm radius, so that their cores overlap (EPA's nearest edge of the hull)."""
    p = LaryngoscopeParams.from_config(haptic_config(None))
    space = pymunk.Space()
    blade = pymunk.Body(p.mass, p.moment)
    poly, segment = pymunk.Poly(blade, p.outline), pymunk.Segment(space.static_body, *p.incisor_segment, INCISOR_RADIUS)
    space.add(blade, poly, segment)
    rng = np.random.default_rng(0)
    n = 4000
    x = p.body_start[0] + rng.uniform(-0.03, 0.03, n)
    y = p.body_start[1] + rng.uniform(-0.002, 0.03, n)
    a = rng.uniform(-0.6, 0.6, n)
    solver = Solver.of(p.incisor_segment, INCISOR_RADIUS, p.outline, 1.0, 1.0, 0.0, 1.0, 0.0, 0.0)
    c, s = np.cos(a), np.sin(a)
    normal, on_segment, on_blade, exists, _ = collide(solver, transformed(solver.local, x, y, c, s),
                                                      transformed(solver.local_normals, x, y, c, s, offset=False), np)
    kinds = {"apart": 0, "touching": 0, "sunk": 0}
    for k in range(n):
        blade.position, blade.angle = (float(x[k]), float(y[k])), float(a[k])
        space.reindex_shapes_for_body(blade)
        found = lib.cpShapesCollide(segment._shape, poly._shape)
        points = [found.points[i] for i in range(found.count)]
        theirs = sorted((q.pointA.x, q.pointA.y, q.pointB.x, q.pointB.y) for q in points)
        mine = sorted((*on_segment[k, i], *on_blade[k, i]) for i in range(2) if exists[k, i])
        assert mine == theirs, k
        if points:
            assert normal[k].tolist() == [found.normal.x, found.normal.y], k
        sunk = any(q.distance <= -INCISOR_RADIUS for q in points)
        kinds["sunk" if sunk else "touching" if points else "apart"] += 1
    assert min(kinds.values()) > 300, kinds                      # every case was tried


def test_the_blade_levered_on_the_incisors_steps_as_pymunk_steps_it_bit_for_bit():
    """8 hands lift the blade's flange onto the incisors (12 mm up, tip up 0.2 rad over 1 s), ease back
    and jitter (random hand velocities and tongue-like forces) for 2,000 substeps: the contact solver
    (the arbiters' cached impulses, their persistence and the contacts' features, the bias velocity of
    position correction, friction) leaves every blade as pymunk does, bit for bit, while the incisors
    carry up to tens of newtons and the blades leave and touch them again."""
    p = LaryngoscopeParams.from_config(haptic_config(None))
    c, n = Coupling.of(p), 8
    devices = [pymunk_device(p, threaded=False, teeth=True) for _ in range(n)]
    solver = Solver.of(p.incisor_segment, INCISOR_RADIUS, p.outline, c.m_inv, c.i_inv, SHAPE_FRICTION * SHAPE_FRICTION,
                       H, COLLISION_SLOP, 1.0 - math.pow(devices[0][0].collision_bias, H))
    teeth = Incisors(solver, Arbiters.none(n), [np.zeros(n), np.zeros(n), np.zeros(n)], np, dt_coef=0.0)
    blade = tuple(np.full(n, v) for v in (*p.body_start, 0.0, 0.0, 0.0, 0.0))
    hand = tuple(np.full(n, v) for v in (*p.grip_start, 0.0))
    rng = np.random.default_rng(0)
    firsts, peak = 0, 0.0
    for k in range(2000):
        lift = np.array([0.0, 0.012, -0.2]) * (1.0 if k < 1000 else -1.0 if k < 1500 else 0.0)
        hand_v, force = lift + rng.normal(0, [0.02, 0.02, 0.2], (n, 3)), rng.normal(0, [2.0, 2.0, 0.05], (n, 3))
        reference = np.array([pymunk_step(d, hand_v[i], force[i]) for i, d in enumerate(devices)])
        blade, hand = coupling_step(blade, hand, tuple(hand_v.T), tuple(force.T), H, c, SOLVER_ITERATIONS, ArrayOps, teeth)
        teeth.dt_coef = 1.0                          # Chipmunk's h / previous h, after a space's first step
        assert np.array_equal(np.stack(blade, axis=1), reference), k
        assert teeth.arbiters.first is not None
        firsts += int(teeth.arbiters.first.sum())
        peak = max(peak, float(teeth.arbiters.jn.max()) / H)
    assert peak > 10.0                               # newtons on the incisors
    assert firsts > 2 * n                            # contacts made, lost and made again


@pytest.mark.parametrize("engine", [LaryngoscopeArrays, LaryngoscopeKernel], ids=["numpy", "compiled"])
@pytest.mark.parametrize("sections, periods, on_incisors, sunk", [
    ({}, 400, 10, 0),
    ({"device": {"coupling_stiffness": 1e6, "blade_mass": 0.01, "handle_mass": 0.0}, "tissue": {"E": 1e7}}, 10, 0, 0),
    ({"tissue": {"E": 1e3}}, 200, 0, 0),
    ({"device": {"max_hand_speed": 5.0, "blade_mass": 0.01, "coupling_damping": 150.0}}, 100, 10, 5),
], ids=["default", "stiff", "soft", "fast"])
def test_every_device_of_the_array_batch_equals_a_single_pymunk_device_bit_for_bit(sections, periods, on_incisors,
                                                                                  sunk, engine):
    """LaryngoscopeArrays (no pymunk space) and LaryngoscopeKernel (its float twin, compiled) against
    single pymunk devices, each of 4 with its own actions: pressing, sweeping, levering on the incisors
    and into the walls, idle; the same state after every control period (blade, hand, lateral, tongue and
    incisor contact, hand velocity) and the same observation. The documented extreme corners
    (``softenv bench``'s): 1e6 N/m coupling, 10 g blade, 10 MPa tongue; a 1 kPa tongue; and a light,
    heavily damped blade driven at 5 m/s, which pymunk finds sunk past the incisors' radius."""
    world = World(scene_config(HAPTIC_SCENES["SoftSphereHaptic-v0"], sections))
    parts = laryngoscope_parts(world.scene, world.config)
    n = 4
    singles, batch = [Laryngoscope(*parts) for _ in range(n)], engine(*parts, n)
    rng = np.random.default_rng(4)
    actions = rng.uniform(-1, 1, (periods, n, 4))
    part = periods // 8
    actions[:3 * part, :, 1] = np.abs(actions[:3 * part, :, 1])      # press into the tongue first
    actions[3 * part:4 * part, :2] = [1.0, 0.0, 0.0, 1.0]             # two insert and lever: the incisors, the walls
    actions[6 * part:6 * part + part // 2] = 0.0
    incisors, deep = 0, []
    for a in actions:
        for single, row in zip(singles, a):
            single.control_step(row.tolist())
            single._blade.each_arbiter(lambda arbiter: deep.extend(q.distance <= -INCISOR_RADIUS for q in
                                                                   arbiter.contact_point_set.points))
        batch.control_step(a)
        t = batch.state()
        for i, single in enumerate(singles):
            s = single.state()
            for field in ("blade", "hand", "lateral", "contact", "hand_velocity"):
                assert np.array_equal(getattr(s, field)[0], getattr(t, field)[i]), (field, i)
            assert single.observation() == batch.observation()[i].tolist()
        incisors += int(np.count_nonzero(batch.incisor_force > 0))
    assert incisors >= on_incisors and sum(deep) >= sunk
