"""The laryngoscope's Warp kernel (softenv.devices.laryngoscope.warp_kernel) against pymunk itself: every
device of a batch, on numpy arrays and on torch's CPU tensors, equals a single pymunk device bit for bit
over whole rollouts (levered on the incisors too); its collision finds what Chipmunk's own (cpShapesCollide) finds, bit for bit; and its
gradients, bridged to torch autograd, match central differences on smooth stretches."""

from __future__ import annotations

import dataclasses

import numpy as np
import pymunk
import pytest
import warp as wp
from pymunk._chipmunk import lib

from softenv.devices.laryngoscope import warp_kernel as K
from softenv.devices.laryngoscope.batch import LaryngoscopeBatch
from softenv.devices.laryngoscope.warp_arrays import LaryngoscopeWarp
from softenv.devices.laryngoscope.params import INCISOR_RADIUS, LaryngoscopeParams
from softenv.devices.laryngoscope.part import laryngoscope_parts
from softenv.devices.laryngoscope.physics import jaw_contact
from softenv.devices.laryngoscope.single import Laryngoscope
from softenv.devices.laryngoscope.state import IncisorContact, polygon_planes
from softenv.envs import HAPTIC_SCENES
from softenv.envs.config import scene_config
from softenv.envs.world import World
from softenv.training.hand import haptic_config

from lever_support import lever_actions

torch = pytest.importorskip("torch")

from softenv.devices.laryngoscope.warp_tensors import LaryngoscopeWarpTensors, differentiable_rollout  # noqa: E402


def _parts(sections):
    world = World(scene_config(HAPTIC_SCENES["SoftSphereHaptic-v0"], sections))
    return laryngoscope_parts(world.scene, world.config)


def _numpy(parts, n):
    return LaryngoscopeWarp(*parts, n)


def _torch(parts, n):
    return LaryngoscopeWarpTensors(*parts, n, "cpu")


@pytest.mark.parametrize("engine", [_numpy, _torch], ids=["numpy", "torch-cpu"])
@pytest.mark.parametrize("sections, periods, on_incisors, sunk", [
    ({}, 400, 10, 0),
    ({"device": {"coupling_stiffness": 1e6, "blade_mass": 0.01, "handle_mass": 0.0}, "tissue": {"E": 1e7}}, 10, 0, 0),
    ({"tissue": {"E": 1e3}}, 200, 0, 0),
    ({"device": {"max_hand_speed": 5.0, "blade_mass": 0.01, "coupling_damping": 150.0}}, 100, 10, 5),
    ({"airway": {"interincisal_gap": 26.0}}, 300, 10, 0),
], ids=["default", "stiff", "soft", "fast", "jaw"])
def test_every_device_of_the_warp_engine_equals_a_single_pymunk_device_bit_for_bit(sections, periods, on_incisors,
                                                                                  sunk, engine):
    """The Warp kernel on numpy arrays and on CPU tensors against single pymunk devices, each of 4 with its
    own actions: pressing, sweeping, levering on the incisors and into the walls, idle; the same state
    after every control period (blade, hand, lateral, tongue and incisor contact, hand velocity) and the
    same observation. The documented extreme corners (``softenv bench``'s): 1e6 N/m coupling, 10 g blade,
    10 MPa tongue; a 1 kPa tongue; a light, heavily damped blade driven at 5 m/s, which pymunk finds
    sunk past the incisors' radius (the collision's EPA branch); and lower incisors 1 mm under the blade,
    the blades resting on the jaw and levered off it onto the upper incisors."""
    parts = _parts(sections)
    n = 4
    singles, batch = [Laryngoscope(*parts) for _ in range(n)], engine(parts, n)
    rng = np.random.default_rng(4)
    actions = rng.uniform(-1, 1, (periods, n, 4))
    part = periods // 8
    actions[:3 * part, :, 1] = np.abs(actions[:3 * part, :, 1])      # press into the tongue first
    actions[3 * part:4 * part, :2] = [1.0, 0.0, 0.0, 1.0]             # two insert and lever: the incisors, the walls
    actions[6 * part:6 * part + part // 2] = 0.0
    incisors, deep, jawed = 0, [], 0
    for a in actions:
        for single, row in zip(singles, a):
            single.control_step(row.tolist())
            jawed += single.jaw_force > 0
            single._blade.each_arbiter(lambda arbiter: deep.extend(q.distance <= -INCISOR_RADIUS for q in
                                                                   arbiter.contact_point_set.points))
        batch.control_step(batch._array(a))
        t = batch.state()
        for i, single in enumerate(singles):
            s = single.state()
            for field in ("blade", "hand", "lateral", "contact", "hand_velocity"):
                assert np.array_equal(getattr(s, field)[0], getattr(t, field)[i]), (field, i)
            assert single.observation() == np.asarray(batch.observation()[i]).tolist()
        incisors += int(np.count_nonzero(np.asarray(batch.incisor_force) > 0))
    assert incisors >= on_incisors and sum(deep) >= sunk
    assert (jawed >= 100) == ("airway" in sections)


@wp.kernel(enable_backward=False, module="unique")
def _collide_poses(poses: wp.array(dtype=wp.vec3d), p: K.Params, local: wp.array(dtype=wp.vec2d),
                   local_normals: wp.array(dtype=wp.vec2d), normal: wp.array(dtype=wp.vec2d),
                   points: wp.array2d(dtype=wp.vec4d), exists: wp.array2d(dtype=int)):
    i = wp.tid()
    x, y, a = poses[i][0], poses[i][1], poses[i][2]
    ca, sa = wp.cos(a), wp.sin(a)
    hit = K.collide(p, K.world_vertices(local, p.vertices, ca, sa, x, y), K.world_normals(local_normals, p.vertices, ca, sa))
    normal[i] = wp.vec2d(hit.nx, hit.ny)
    points[i, 0] = hit.p0
    points[i, 1] = hit.p1
    exists[i, 0] = hit.ex[0]
    exists[i, 1] = hit.ex[1]


def _outline(p: LaryngoscopeParams, vertices: int) -> list[tuple[float, float]]:
    """The blade's own outline (5 vertices), or a convex polygon of ``vertices`` corners on the ellipse
    through its length and flange height, about its middle (other counts the kernel holds, up to 8)."""
    if vertices == 5:
        return p.outline
    (x0, y0), (x1, y1) = p.body_point(-p.blade_length, 0.0), p.body_point(0.0, p.flange_height)
    angles = np.linspace(0.0, 2 * np.pi, vertices, endpoint=False) + 0.3
    return [((x0 + x1) / 2 + (x1 - x0) / 2 * np.cos(t), (y0 + y1) / 2 + (y1 - y0) / 2 * np.sin(t)) for t in angles]


@pytest.mark.parametrize("vertices", [5, 3, 8])
def test_the_blade_meets_the_incisors_where_chipmunk_finds_it_bit_for_bit(vertices):
    """4,000 blade poses around the incisors (3 cm back and forth, 2 mm below to 30 mm into them,
    +-0.6 rad): the contact normal, the points on both surfaces and how many there are equal Chipmunk's own
    collision of the two shapes, where the cores stay apart (GJK's closest points) and where the blade sinks
    deeper than the incisors' 4 mm radius, so that their cores overlap (EPA's nearest edge of the hull); for
    the blade's outline and for polygons of 3 and 8 corners (the candidate edges depend on the count)."""
    p = LaryngoscopeParams.from_config(haptic_config(None))
    space = pymunk.Space()
    blade = pymunk.Body(p.mass, p.moment)
    poly = pymunk.Poly(blade, _outline(p, vertices))
    segment = pymunk.Segment(space.static_body, *p.incisor_segment, INCISOR_RADIUS)
    space.add(blade, poly, segment)
    rng = np.random.default_rng(0)
    n = 4000
    poses = np.stack([p.body_start[0] + rng.uniform(-0.03, 0.03, n), p.body_start[1] + rng.uniform(-0.002, 0.03, n),
                      rng.uniform(-0.6, 0.6, n)], axis=1)
    contact = IncisorContact.of(p, 1e-3)
    local, local_normals = polygon_planes([tuple(v) for v in poly.get_vertices()])    # in Chipmunk's order
    assert len(local) == vertices
    contact = dataclasses.replace(contact, local=local, local_normals=local_normals)
    params = K.Params()
    params.end0, params.end1 = wp.vec2d(*contact.ends[0]), wp.vec2d(*contact.ends[1])
    params.seg_normal, params.radius, params.vertices = wp.vec2d(*contact.seg_normal), contact.radius, len(contact.local)
    normal = wp.zeros(n, dtype=wp.vec2d)
    points = wp.zeros((n, 2), dtype=wp.vec4d)
    exists = wp.zeros((n, 2), dtype=int)
    wp.launch(_collide_poses, n, inputs=[wp.array(poses, dtype=wp.vec3d), params,
                                         wp.array(contact.local, dtype=wp.vec2d),
                                         wp.array(contact.local_normals, dtype=wp.vec2d), normal, points, exists])
    normal, points, exists = normal.numpy(), points.numpy(), exists.numpy()
    kinds = {"apart": 0, "touching": 0, "sunk": 0}
    for k, (x, y, a) in enumerate(poses):
        blade.position, blade.angle = (float(x), float(y)), float(a)
        space.reindex_shapes_for_body(blade)
        found = lib.cpShapesCollide(segment._shape, poly._shape)
        theirs_points = [found.points[i] for i in range(found.count)]
        theirs = sorted((q.pointA.x, q.pointA.y, q.pointB.x, q.pointB.y) for q in theirs_points)
        mine = sorted(tuple(points[k, i].tolist()) for i in range(2) if exists[k, i])
        assert mine == theirs, k
        if theirs_points:
            assert normal[k].tolist() == [found.normal.x, found.normal.y], k
        sunk = any(q.distance <= -INCISOR_RADIUS for q in theirs_points)
        kinds["sunk" if sunk else "touching" if theirs_points else "apart"] += 1
    assert min(kinds.values()) > 300, kinds                      # every case was tried


def _loss_weights(periods, n):
    rng = np.random.default_rng(7)
    return {"blade": rng.normal(size=(periods, n, 6)), "lateral": rng.normal(size=(periods, n, 4)),
            "contact": rng.normal(size=(periods, n, 4)) * np.array([1e-2, 1e-2, 1.0, 1.0])}


def _loss(rollout, weights):
    return sum(float(np.sum(np.asarray(rollout[k]) * w)) if isinstance(rollout[k], np.ndarray) else
               (rollout[k] * torch.as_tensor(w)).sum() for k, w in weights.items())


@pytest.mark.parametrize("stretch", ["free", "on-the-tongue", "on-the-jaw"])
def test_gradients_through_the_warp_kernel_match_central_differences(stretch):
    """Two control periods (40 substeps) of one device, through torch autograd (Warp's adjoint of every
    substep, :func:`differentiable_rollout`), against central differences (step 1e-6, float64) of the fast
    kernel (:func:`control_period`) from the perturbed start: the gradient of a weighted sum of every
    period's blade, lateral and contact state with respect to the start state (blade, hand, lateral) and
    the actions, within 1e-6 of the largest component (measured: 5e-8 for the actions, 1e-10 for the
    start state). Free in the air, pressed into the tongue (its contact on throughout, a smooth stretch of
    its load table), and pressed onto lower incisors (the jaw's spring on throughout, the tongue off); the
    upper incisors untouched in all three."""
    parts = _parts({"airway": {"interincisal_gap": 26.0}} if stretch == "on-the-jaw" else {})
    engine, reference = LaryngoscopeWarpTensors(*parts, 1), LaryngoscopeWarp(*parts, 1)
    for _ in range(30 if stretch != "free" else 0):
        reference.control_step(np.array([[0.0, 0.6, 0.2, 0.0]]))
    start = reference.state()
    actions = np.array([[[0.3, 0.2, -0.2, 0.1]], [[-0.1, 0.3, 0.1, 0.2]]])
    weights = _loss_weights(len(actions), 1)

    def fast(blade, hand, lateral, acts):
        reference.load_state(type(start)(blade, hand, lateral, start.contact, start.hand_velocity))
        out = {"blade": [], "lateral": [], "contact": []}
        for a in acts:
            reference.control_step(a)
            s = reference.state()
            out["blade"].append(s.blade)
            out["lateral"].append(s.lateral)
            out["contact"].append(s.contact[:, :4])
        return _loss({k: np.stack(v) for k, v in out.items()}, weights), out

    _, plain = fast(start.blade, start.hand, start.lateral, actions)
    assert (np.stack(plain["contact"])[..., 0] > 0).all() == (stretch == "on-the-tongue")
    assert (np.stack(plain["contact"])[..., 0] > 0).any() == (stretch == "on-the-tongue")
    if stretch == "on-the-jaw":
        x, y, a = np.stack(plain["blade"])[..., :3].reshape(-1, 3).T
        assert (jaw_contact(x, y, np.cos(a), np.sin(a), reference.c)[0] > 0).all()
    inputs = [torch.tensor(x, requires_grad=True) for x in (start.blade, start.hand, start.lateral, actions)]
    rollout = differentiable_rollout(engine, *inputs)
    assert (rollout["incisor"] == 0).all()
    for k in ("blade", "lateral"):                       # the differentiable path's forward is the fast one's
        assert np.array_equal(rollout[k].detach().numpy(), np.stack(plain[k]))
    _loss(rollout, weights).backward()
    eps = 1e-6
    for x, tensor in zip((start.blade, start.hand, start.lateral, actions), inputs):
        numeric = np.zeros_like(x)
        for idx in np.ndindex(x.shape):
            step = np.zeros_like(x)
            step[idx] = eps
            args = [start.blade, start.hand, start.lateral, actions]
            which = [a is x for a in args].index(True)
            up, down = list(args), list(args)
            up[which], down[which] = x + step, x - step
            numeric[idx] = (fast(*up)[0] - fast(*down)[0]) / (2 * eps)
        scale = np.abs(numeric).max()
        assert scale > 0
        np.testing.assert_allclose(tensor.grad.numpy(), numeric, rtol=0, atol=1e-6 * scale)


def test_a_blade_levered_on_the_incisors_presses_the_tongue_by_its_law_in_every_engine():
    """Levered on the incisors to 30 N and held, the tongue's normal force is its contact law at the
    blade's depth (within 0.2 %): the stiff contact's implicit barrier predicts the incisors' push on the
    blade as well as the coupling's (predicting the coupling's alone left it 9 % under the law). The
    pymunk batch and the Warp kernel on numpy arrays and on torch tensors follow the single device bit
    for bit, so each predicts the teeth's push as the single device does."""
    parts = _parts({})
    single = Laryngoscope(*parts)
    actions = lever_actions(single, 30.0, 100, 40)
    depth = single.penetration()
    law = float(single.contact.load(np.array([depth]))[0])
    assert single.incisor_force > 20.0 and single.c.k_ref < single.contact.stiffness(depth)   # levered, stiff
    assert single.normal_force == pytest.approx(law, rel=2e-3) and law > 29.0
    replay = Laryngoscope(*parts)
    engines = [LaryngoscopeBatch(*parts, 1), _numpy(parts, 2), _torch(parts, 2)]
    for action in actions:
        replay.control_step(action)
        s = replay.state()
        for engine in engines:
            engine.control_step(engine._array(np.array([action] * engine.n)))
            t = engine.state()
            for field in ("blade", "hand", "lateral", "contact", "hand_velocity"):
                for i in range(engine.n):
                    assert np.array_equal(np.asarray(getattr(s, field)[0]), np.asarray(getattr(t, field)[i])), \
                        (type(engine).__name__, field, i)
    assert replay.state().contact.tolist() == single.state().contact.tolist()
