"""The simulated laryngoscope's physics: contact law against the analytic tissue, time stepping against
the analytic damped oscillator, incisor forces against statics, stiff and extreme cases, energy,
single-versus-batched agreement, the haptic presets and the haptic loop."""

import math

import numpy as np
import pymunk
import pytest

from softenv.devices.contact import TongueContact
from softenv.devices.laryngoscope.batch import LaryngoscopeBatch
from softenv.devices.laryngoscope.params import ACCURACY, JAW_STIFFNESS, LaryngoscopeParams, substep_count
from softenv.devices.laryngoscope.part import laryngoscope_parts
from softenv.devices.laryngoscope.single import Laryngoscope
from softenv.devices.laryngoscope.space import COLLISION_SLOP, virtual_coupling
from softenv.devices.haptic_presets import PRESETS, render_force
from softenv.envs import HAPTIC_SCENES
from softenv.envs.config import scene_config
from softenv.envs.world import World
from softenv.haptics import HapticLoop
from softenv.tissue import AnalyticTissue

from lever_support import jaw_depth

PRESS, HOLD = [0.0, 0.9, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0]
JAW = {"airway": {"interincisal_gap": 26.0}}      # lower incisors 1 mm under the blade in the start pose


def make_world(**sections) -> World:
    return World(scene_config(HAPTIC_SCENES["SoftSphereHaptic-v0"], sections))


def make_device(**sections) -> Laryngoscope:
    world = make_world(**sections)
    return Laryngoscope(*laryngoscope_parts(world.scene, world.config))


def coupling_pull(dev: Laryngoscope) -> np.ndarray:
    """The coupling's translational force on the blade, ``k (hand - grip)``, from the state alone."""
    x, y, a, *_, gx, gy, _ = dev.kinematics()
    qx, qy = dev.params.grip
    grip = np.array([x + math.cos(a) * qx - math.sin(a) * qy, y + math.sin(a) * qx + math.cos(a) * qy])
    return dev.params.coupling_stiffness * (np.array([gx, gy]) - grip)


@pytest.mark.parametrize("law", ["linear", "stiffening"])
def test_a_held_press_reaches_the_analytic_tissues_static_indentation(law):
    dev = make_device(tissue={"law": law})
    for _ in range(8):
        dev.control_step(PRESS)
    for _ in range(100):                                      # 2 s held: settled
        dev.control_step(HOLD)
    P = dev.normal_force
    assert 15.0 < P < 60.0                                    # a clinical press
    # the indentation the analytic tissue gives for the force the blade exerts: an independent computation
    world = make_world(tissue={"law": law})
    R = world.scene.tissue.radius
    W = AnalyticTissue(world.scene.mesh, world.scene.tissue).amplitudes([[0.0, 0.0, R]], [[0.0, 0.0, -P]])["indentation"][0]
    assert dev.penetration() == pytest.approx(W, rel=0.02)
    # and that force is what the hand pushes with (statics: coupling and tongue balance)
    assert np.linalg.norm(coupling_pull(dev)) == pytest.approx(P, rel=0.02)


def test_contact_law_inverts_the_indentation_and_its_potential_integrates_it():
    world = make_world(tissue={"law": "stiffening"})
    law = TongueContact(world.scene.contact_curve(40.0), 0.5)
    loads = np.array([0.5, 5.0, 20.0, 40.0, 80.0])
    np.testing.assert_allclose(law.load(law.indentation(loads)), loads, rtol=1e-3)
    assert law.load(np.array([-1e-3, 0.0]))[0] == 0.0
    d = np.linspace(1e-4, 0.8 * law.step * 4096, 7)
    fd = (law.potential(d + 1e-7) - law.potential(d - 1e-7)) / 2e-7   # dU/d(delta) = P
    np.testing.assert_allclose(fd, law.load(d), rtol=1e-4)


def ringing(xs: np.ndarray, h: float) -> tuple[float, float]:
    """Period (from zero crossings, interpolated) and the ratio of successive half-cycle peaks of a
    decaying oscillation sampled every ``h``."""
    t = (np.arange(len(xs)) + 1) * h
    i = np.flatnonzero(np.sign(xs[:-1]) * np.sign(xs[1:]) < 0)
    crossings = t[i] - xs[i] * h / (xs[i + 1] - xs[i])
    peaks = [np.abs(xs[i[j]:i[j + 1] + 1]).max() for j in range(3)]
    return 2 * float(np.mean(np.diff(crossings[:6]))), peaks[1] / peaks[0]


def assert_rings_like_the_analytic_oscillator(xs: np.ndarray, h: float, k: float, c: float, m: float) -> None:
    omega, zeta = math.sqrt(k / m), c / (2 * math.sqrt(k * m))
    assert omega * h <= ACCURACY
    wd = omega * math.sqrt(1 - zeta ** 2)
    period, decay = ringing(xs, h)
    assert period == pytest.approx(2 * math.pi / wd, rel=0.01)
    assert decay == pytest.approx(math.exp(-zeta * omega * math.pi / wd), rel=0.01)


@pytest.mark.parametrize("mode", ["x", "y", "angle"])
def test_the_coupling_rings_like_the_analytic_damped_oscillator(mode):
    """A body on the device's coupling (anchor at its centre of mass, so translation and rotation
    decouple) at the device's default masses and substep: period and decay within 1 %."""
    p = LaryngoscopeParams(radius=0.03, dt=0.02)
    space = pymunk.Space()
    hand = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
    body = pymunk.Body(p.mass, p.moment)
    space.add(hand, body, *virtual_coupling(hand, body, (0.0, 0.0), p))
    if mode == "angle":
        body.angle = 0.05
        k, c, m = p.rotational_stiffness, p.rotational_damping, p.moment
    else:
        body.position = (0.002, 0.0) if mode == "x" else (0.0, 0.002)
        k, c, m = p.coupling_stiffness, p.coupling_damping, p.mass
    h = p.dt / substep_count(p.dt, math.sqrt(k / m), p.max_substep)
    read = {"x": lambda: body.position.x, "y": lambda: body.position.y, "angle": lambda: body.angle}[mode]
    xs = []
    for _ in range(int(0.6 / h)):
        space.step(h)
        xs.append(read())
    assert_rings_like_the_analytic_oscillator(np.array(xs), h, k, c, m)


def test_the_lateral_sweep_rings_like_the_analytic_damped_oscillator():
    dev = make_device()                                       # off the tongue: only the coupling holds it
    state = dev.state()
    state.lateral[0, 0] = 0.002                               # blade 2 mm to the side of the hand
    dev.load_state(state)
    ys = []
    for _ in range(int(0.4 / dev.h)):
        dev.substeps(0.0, 0.0, 0.0, 0.0, 1)
        ys.append(dev._lateral[0])
    p = dev.params
    assert_rings_like_the_analytic_oscillator(np.array(ys), dev.h, p.coupling_stiffness, p.coupling_damping, p.mass)


def test_substeps_follow_the_stiffest_spring():
    base = make_device()
    assert base.h <= 1e-3 and base.params.omega_max(base.contact) * base.h <= ACCURACY
    stiff = make_device(device={"coupling_stiffness": 1e6, "blade_mass": 0.01, "handle_mass": 0.0})
    omega = stiff.params.omega_max(stiff.contact)
    assert omega > math.sqrt(1e6 / 0.01)                      # at least the translational mode
    assert stiff.n_substeps == math.ceil(stiff.params.dt * omega / ACCURACY - 1e-9)
    hard = make_device(tissue={"E": 1e7})
    assert hard.n_substeps > 3 * base.n_substeps              # a stiff tongue's lateral grip needs shorter steps
    jaw = make_device(**JAW)                                  # the jaw's spring, explicit, is counted
    omega = jaw.params.omega_max(jaw.contact)
    assert omega > math.sqrt(JAW_STIFFNESS / jaw.params.mass) and jaw.n_substeps > base.n_substeps
    assert jaw.n_substeps == math.ceil(jaw.params.dt * omega / ACCURACY - 1e-9)
    for dev in (base, stiff, hard, jaw):
        # the normal contact's explicit part adds no substeps to those the rest of the device needs;
        # what it leaves out goes to the implicit barrier
        p, contact = dev.params, dev.contact
        without = substep_count(p.dt, p._mode_omega(0.0, contact.lateral_stiffness), p.max_substep)
        assert dev.n_substeps == max(without, math.ceil(p.dt / p.max_substep - 1e-9))
        assert 0.0 < p.explicit_contact_stiffness(contact) <= contact.reference_stiffness
    assert base.params.explicit_contact_stiffness(base.contact) < base.contact.reference_stiffness


def test_levering_loads_the_incisors_and_a_straight_press_does_not():
    dev = make_device()
    for _ in range(30):
        dev.control_step(PRESS if _ < 8 else HOLD)
        assert dev.incisor_force == 0.0
    dev = make_device()
    peak = 0.0
    for _ in range(30):
        dev.control_step([0.0, 0.0, 0.0, -1.0])                  # wrist pitched tip-up: the flange meets the teeth
        peak = max(peak, dev.incisor_force)
    assert peak > 1.0
    dev = make_device()                                         # pushed up into the teeth, then held: statics
    for _ in range(3):
        dev.control_step([0.0, -0.9, 0.0, 0.0])
    for _ in range(100):
        dev.control_step(HOLD)
    assert dev.normal_force == 0.0
    assert dev.incisor_force == pytest.approx(np.linalg.norm(coupling_pull(dev)), rel=0.01)


def test_a_blade_pressed_onto_the_lower_incisors_rests_on_the_jaw():
    """Lower incisors 1 mm under the blade: the same press that indents the tongue without them comes to
    rest on the jaw, clear of the tongue and the upper teeth, the jaw's spring squeezed by the coupling's
    pull over its stiffness (statics: the two balance); the blade, levered up, leaves the jaw."""
    dev, free = make_device(**JAW), make_device()
    for period in range(108):
        for d in (dev, free):
            d.control_step(PRESS if period < 8 else HOLD)
    depth, push = jaw_depth(dev), dev.jaw_force
    pull = np.linalg.norm(coupling_pull(dev))
    assert free.normal_force > 15.0 and jaw_depth(free) == -math.inf and free.jaw_force == 0.0
    assert dev.normal_force == 0.0 and dev.incisor_force == 0.0 and push > 15.0
    assert push == pytest.approx(pull, rel=0.01)
    assert depth == pytest.approx(pull / JAW_STIFFNESS, rel=0.01)
    for _ in range(30):
        dev.control_step([0.0, -1.0, 0.0, -1.0])
    assert dev.jaw_force == 0.0 and dev.incisor_force > 1.0


EXTREMES = {
    "default": {},
    "stiff coupling, 10 g blade": {"device": {"coupling_stiffness": 1e6, "blade_mass": 0.01, "handle_mass": 0.0}},
    "soft tongue (1 kPa)": {"tissue": {"E": 1e3}},
    "stiff tongue (10 MPa)": {"tissue": {"E": 1e7}},
    "lower incisors 1 mm under the blade": JAW,
}


@pytest.mark.parametrize("name", list(EXTREMES))
@pytest.mark.parametrize("action", [[0.0, -1.0, 0.0, -1.0], [1.0, 1.0, 1.0, 1.0]], ids=["into-incisors", "into-tongue"])
def test_full_speed_into_teeth_or_tongue_stays_finite_and_never_tunnels(name, action):
    dev = make_device(**EXTREMES[name])
    steps = 250 if dev.n_substeps < 100 else 12               # a whole episode, or 0.25 s at 2,000 substeps
    for _ in range(steps):
        dev.control_step(action)
        assert all(math.isfinite(v) for v in dev.kinematics()) and math.isfinite(dev.normal_force)
        # the incisors stay outside the blade (to pymunk's slop plus a fraction of a millimetre)
        assert dev.incisor_clearance() > -1e-3
        # the blade never passes the tongue's saturation barrier (80 % of the radius)
        assert dev.penetration() < 0.83 * dev.c.R
        # nor sinks onto the lower incisors by half the flange's height
        assert jaw_depth(dev) < 0.5 * dev.params.flange_height


@pytest.mark.parametrize("name", list(EXTREMES))
@pytest.mark.parametrize("stir", [[0.3, 1.0, 0.5, 0.3], [1.0, 1.0, 1.0, 1.0], [0.0, -1.0, 0.0, -1.0]],
                         ids=["press-and-sweep", "into-tongue", "into-incisors"])
def test_energy_never_grows_without_input(name, stir):
    dev = make_device(**EXTREMES[name])
    for _ in range(5 if dev.n_substeps < 100 else 3):
        dev.control_step(stir)                                # stir it up
    energy, incisor = [dev.energy()[0]], 0.0
    for _ in range(60 if dev.n_substeps < 100 else 6):
        dev.control_step(HOLD)                                # the hand holds still
        energy.append(dev.energy()[0])
        incisor = max(incisor, dev.incisor_force)
    energy = np.array(energy)
    # no energy gained. Pressed against the saturated tongue's stiff barrier a blade may ring, bounded;
    # pressed on the teeth, pymunk's contact pushes it out of their overlap (at most the slop), doing
    # work that no potential of ours counts: at most the incisor force times the slop
    allowed = 1e-3 * energy[0] + incisor * COLLISION_SLOP
    assert energy.max() <= energy[0] + allowed
    assert energy[-1] <= energy[0] + allowed


def test_a_batch_equals_single_devices():
    """Device 0 of a batch (at the origin) equals a single device bit for bit; the others, whose
    positions carry their place's offset, agree to rounding."""
    world = make_world()
    params, contact = laryngoscope_parts(world.scene, world.config)
    batch = LaryngoscopeBatch(params, contact, 3)
    singles = [Laryngoscope(params, contact) for _ in range(3)]
    rng = np.random.default_rng(0)
    for _ in range(60):
        actions = rng.uniform(-1, 1, (3, 4))
        actions[:, 1] = np.abs(actions[:, 1])                # mostly pressing: contact with the tongue
        batch.control_step(actions)
        for s, a in zip(singles, actions):
            s.control_step(a.tolist())
        got = batch.state()
        for i, s in enumerate(singles):
            want = s.state()
            if i == 0:
                assert np.array_equal(got.blade[0], want.blade[0]) and np.array_equal(got.contact[0], want.contact[0])
                assert np.array_equal(got.lateral[0], want.lateral[0])
            np.testing.assert_allclose(got.blade[i], want.blade[0], rtol=1e-9, atol=1e-11)
            np.testing.assert_allclose(got.contact[i, :5], want.contact[0, :5], rtol=1e-7, atol=1e-7)
    assert np.array_equal(batch.observation()[0], np.array(singles[0].observation()))
    assert np.array_equal(batch.haptic_force()[0], singles[0].haptic_force()[0])


def test_the_tracked_hand_is_where_chipmunk_put_it():
    dev = make_device()
    for a in np.random.default_rng(1).uniform(-1, 1, (40, 4)):
        dev.control_step(a.tolist())
        gx, gy, pitch = dev._hand_pose
        assert (gx, gy) == tuple(dev._hand.position) and pitch == dev._hand.angle


def test_haptic_presets_scale_to_the_device_and_saturate():
    omega = PRESETS["omega"]
    small = render_force(np.array([1.0, 0.0, 2.0]), 1e4, omega)        # 1e4 N/m coupling, 5e3 N/m device
    np.testing.assert_allclose(small, [0.5, 0.0, 1.0])
    big = render_force(np.array([300.0, 0.0, -400.0]), 2000.0, omega)
    assert np.linalg.norm(big) == pytest.approx(omega.max_force)
    np.testing.assert_allclose(big / np.linalg.norm(big), [0.6, 0.0, -0.8])


def test_the_haptic_loop_renders_the_press_within_the_preset():
    loop = HapticLoop(device={"haptic_preset": "falcon"})
    start = loop.hand_pose
    assert np.allclose(loop.tick(start), 0.0)                  # at rest, nothing to feel
    forces = loop.run([start - [0.0, 0.03 * min(i, 500) / 500, 0.0, 0.0] for i in range(800)])
    assert np.isfinite(forces).all()
    assert np.linalg.norm(forces, axis=1).max() <= PRESETS["falcon"].max_force * (1 + 1e-12)
    assert forces[-1, 2] > 1.0                                 # the tongue pushes the hand back up
    assert loop.device.normal_force > 10.0
    surface = loop.surface().reshape(-1, 3)
    assert surface.shape == loop.world.scene.mesh.vertices.shape
    assert surface[:, 2].max() < loop.world.scene.tissue.radius - 1e-3   # the dorsum is pressed down
    far = loop.tick(start + [1.0, 1.0, 0.0, 0.0])              # far outside: projected onto the workspace
    assert np.isfinite(far).all() and loop.hand_pose[0] <= loop.device.params.hand_box[1][0]
    with pytest.raises(ValueError, match="hand_pose"):
        loop.tick([np.nan, 0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="env_id"):
        HapticLoop("SoftSphere-v0")


@pytest.mark.parametrize("sections, periods, on_incisors", [
    ({}, 400, 10),
    ({"device": {"coupling_stiffness": 1e6, "blade_mass": 0.01, "handle_mass": 0.0}, "tissue": {"E": 1e7}}, 40, 0),
    (JAW, 400, 10),
], ids=["default", "stiff", "jaw"])
def test_one_device_on_floats_equals_the_batch_on_arrays_bit_for_bit(sections: dict, periods: int,
                                                                     on_incisors: int) -> None:
    """The single device (Python floats, its hand-inlined loop) against the batch's device 0 (numpy,
    ``pymunk.batch``): the same state after every control period, bit for bit but for the sign of zero, over pressing, sweeping,
    levering and idle periods, in contact with the tongue and the incisors and at the walls; on the
    default scene, on the stiffest corner (1e6 N/m coupling, 10 g blade, 10 MPa tongue: 1,826
    substeps a period, the implicit barrier at work; too short a run to reach the incisors) and with lower
    incisors under the blade (the jaw pressed, with the upper incisors too)."""
    world = make_world(**sections)
    parts = laryngoscope_parts(world.scene, world.config)
    single, batch = Laryngoscope(*parts), LaryngoscopeBatch(*parts, 1)
    rng = np.random.default_rng(4)
    actions = rng.uniform(-1, 1, (periods, 4))
    part = periods // 8
    actions[:3 * part, 1] = np.abs(actions[:3 * part, 1])         # press into the tongue first
    actions[3 * part:4 * part] = [1.0, 0.0, 0.0, 1.0]             # insert and lever: the incisors, the walls
    actions[6 * part:6 * part + part // 2] = 0.0
    touched = incisors = jawed = 0
    for a in actions:
        single.control_step(a.tolist())
        batch.control_step(a[None])
        jawed += single.jaw_force > 0
        s, t = single.state(), batch.state()
        for field in ("blade", "hand", "lateral", "contact", "hand_velocity"):
            assert np.array_equal(getattr(s, field), getattr(t, field)), field     # (zero's sign may differ)
        assert single.observation() == batch.observation()[0].tolist()
        assert single.jaw_force == batch.jaw_force[0]
        touched += single.normal_force > 0
        incisors += single.incisor_force > 0
    assert touched > periods // 4 and incisors >= on_incisors
    assert (jawed >= 10) == ("airway" in sections)


@pytest.mark.parametrize("sections", [{}, {"device": {"coupling_stiffness": 1e6, "blade_mass": 0.01, "handle_mass": 0.0},
                                           "tissue": {"E": 1e7}}], ids=["default", "stiff"])
def test_the_float_kernel_equals_the_ops_kernel_bit_for_bit(sections: dict) -> None:
    """``tongue_substep_floats`` (what the single device runs) against ``tongue_substep`` with
    ``ScalarOps`` (its source) on 20,000 random states: blades clear of the tongue, touching it and pressed
    deep into its barrier and wall (past the table's last node), levelled and tipped, still and fast,
    stuck and sliding sideways, clear of the incisors and levered on them. Every output is the same float, bit for bit (the sign of zero included)."""
    import struct

    from softenv._ops import ScalarOps
    from softenv.devices.laryngoscope.physics import tongue_substep, tongue_substep_floats

    dev = make_device(**sections)
    c, loads, slopes = dev.c, dev.contact.loads_list, dev.contact.slopes_list
    bx, by = dev.params.body_start
    rng = np.random.default_rng(11)
    touched = deep = slid = 0
    for _ in range(20_000):
        a = rng.uniform(-0.6, 0.6)
        blade = (bx + rng.uniform(-0.04, 0.03), by - rng.uniform(-0.01, 0.9) * c.R, a, math.cos(a), math.sin(a),
                 *rng.normal(0.0, 0.3, 2), rng.normal(0.0, 3.0))
        hand = (*(np.array(blade[:2]) + rng.normal(0.0, 0.01, 2) + dev.params.grip), a + rng.normal(0.0, 0.1),
                *rng.normal(0.0, 0.2, 3))
        lateral = tuple(rng.normal(0.0, 0.01, 4))
        teeth = (0.0, 0.0, 0.0) if rng.random() < 0.5 else (*rng.normal(0.0, 20.0, 2), rng.normal(0.0, 2.0))
        args = (blade, hand, lateral, rng.normal(0.0, 0.1), teeth, loads, slopes, c)
        ours, source = tongue_substep_floats(*args), tongue_substep(*args, ScalarOps)
        assert [struct.pack("<d", float(x)) for x in ours] == [struct.pack("<d", float(x)) for x in source], args
        touched += source[3] > 0
        deep += source[3] > 5 * dev.params.max_normal_force
        slid += source[3] > 0 and abs(source[4]) == c.mu * source[3]
    assert touched > 5_000 and deep > 100 and slid > 100         # every branch was taken
