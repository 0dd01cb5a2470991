"""Gradients through whole episodes of the torch twin (``differentiable=True``), on both device kinds: the
same values as the plain twin bit for bit, gradients of the episode's reward with respect to every action
against central finite differences in float64, the graph kept through an autoreset, cut by ``detach()``,
and the settings it cannot take refused by name."""

from dataclasses import replace

import gymnasium as gym
import numpy as np
import pytest
import torch

import softenv  # noqa: F401  (registers the ids)
from softenv.devices.contact import TABLE_INTERVALS, TongueContact, analytic_curve, depth_derivative
from softenv.geometry import latlong_mesh
from softenv.envs.scene import DEPTH_STEP, depth_sensitivity
from softenv.response import ExactResponse
from softenv.tissue import AnalyticTissue, TissueParams

RELATIVE_BOUND = 1e-6     # central differences at step 1e-6 in float64 agree to ~1e-8 of the gradient's scale


DEVICES = [pytest.param("cpu"), pytest.param("cuda", marks=pytest.mark.skipif(not torch.cuda.is_available(),
                                                                               reason="needs a CUDA device"))]


def _rollout(env_id: str, actions: torch.Tensor, differentiable: bool, torch_device: str = "cpu",
             **scene) -> tuple[torch.Tensor, object]:
    """Each step's reward ``(T, n)`` of ``actions`` ``(T, n, 4)`` from ``reset(seed=0)``, and the env. The
    laryngoscope runs on Warp either way (with gradients on it always does; on CUDA the plain step would
    pick Triton, equal to Warp only to rounding)."""
    env = gym.make_vec(f"softenv:{env_id}", num_envs=actions.shape[1], vectorization_mode="vector_entry_point",
                       backend="torch", differentiable=differentiable, torch_device=torch_device,
                       device={"batch_engine": "warp"}, **scene)
    env.reset(seed=0)
    rewards = [env.step(a)[1] for a in actions]
    return torch.stack(rewards), env


def _actions(steps: int, n: int, seed: int, press: float) -> torch.Tensor:
    a = np.random.default_rng(seed).uniform(-0.3, 0.3, (steps, n, 4))
    a[:, :, 1] += press                    # the laryngoscope's press axis: onto the tongue within the episode
    return torch.as_tensor(a)


CASES = {
    "ideal, reach": ("SoftSphere-v0", 25, 0.0, {}),
    "ideal, creep": ("SoftSphereViscoelastic-v0", 25, 0.0, {}),
    "ideal, procedure": ("SoftSphereProcedure-v0", 25, 0.0, {}),
    "laryngoscope, pressing": ("SoftSphereHaptic-v0", 40, 0.6, {}),
}


@pytest.mark.parametrize("torch_device", DEVICES)
@pytest.mark.parametrize("case", CASES, ids=list(CASES))
def test_episode_gradients_match_central_differences(case, torch_device):
    env_id, steps, press, scene = CASES[case]
    a0 = _actions(steps, 2, 1, press).to(torch_device)
    plain, _ = _rollout(env_id, a0, False, torch_device, **scene)
    a = a0.clone().requires_grad_(True)
    rewards, _ = _rollout(env_id, a, True, torch_device, **scene)
    assert torch.equal(rewards.detach(), plain)                  # the same step, bit for bit
    rewards.sum().backward()
    assert a.grad.abs().sum() > 0
    scale = a.grad.abs().max().item()
    rng = np.random.default_rng(2)
    for _ in range(4):                                             # entries across the episode, both envs, all axes
        i = (int(rng.integers(steps)), int(rng.integers(2)), int(rng.integers(4)))
        up, down = a0.clone(), a0.clone()
        up[i] += 1e-6
        down[i] -= 1e-6
        fd = (_rollout(env_id, up, False, torch_device, **scene)[0].sum()
              - _rollout(env_id, down, False, torch_device, **scene)[0].sum()) / 2e-6
        assert abs(a.grad[i].item() - fd.item()) <= RELATIVE_BOUND * scale + 1e-9, (i, a.grad[i].item(), fd.item())


def test_the_graph_survives_an_autoreset_and_detach_cuts_it():
    """An episode that ends inside the rollout starts the next with the state written out of place (no
    in-place error at backward); after ``detach()`` later rewards have no gradient to earlier actions."""
    a = _actions(12, 2, 3, 0.0).requires_grad_(True)
    env = gym.make_vec("softenv:SoftSphere-v0", num_envs=2, vectorization_mode="vector_entry_point", backend="torch",
                       differentiable=True, task={"horizon": 5})
    env.reset(seed=0)
    rewards = torch.stack([env.step(x)[1] for x in a[:8]])             # ends at step 5, next-step autoreset at 6
    rewards.sum().backward()
    assert a.grad[:5].abs().sum() > 0 and a.grad[8:].abs().sum() == 0
    a.grad = None
    env.unwrapped.detach()
    late = torch.stack([env.step(x)[1] for x in a[8:]])
    late.sum().backward()
    assert a.grad[:8].abs().sum() == 0 and a.grad[8:].abs().sum() > 0


def test_settings_it_cannot_differentiate_are_refused_by_name():
    make = dict(num_envs=2, vectorization_mode="vector_entry_point", backend="torch")
    with pytest.raises(ValueError, match="differentiable=True steps eagerly: it takes neither compile_options"):
        gym.make_vec("softenv:SoftSphere-v0", differentiable=True, target_draw="device", compile_options={}, **make)
    with pytest.raises(ValueError, match="differentiable='yes' must be True or False"):
        gym.make_vec("softenv:SoftSphere-v0", differentiable="yes", **make)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="Triton runs on CUDA only")
def test_the_triton_engine_is_refused_and_auto_runs_warp_with_gradients_on():
    make = dict(num_envs=2, vectorization_mode="vector_entry_point", backend="torch", torch_device="cuda",
                differentiable=True)
    with pytest.raises(ValueError, match="device.batch_engine='triton' has no adjoint"):
        gym.make_vec("softenv:SoftSphereHaptic-v0", device={"batch_engine": "triton"}, **make)
    env = gym.make_vec("softenv:SoftSphereHaptic-v0", **make)
    assert type(env.unwrapped._device.laryngoscopes).__name__ == "LaryngoscopeWarpTensors"


def test_a_taped_period_holds_every_field_of_the_rollout_as_the_state_it_replaces():
    from softenv.devices.laryngoscope.tensors import LaryngoscopeTensors
    from softenv.devices.laryngoscope.warp_tensors import HELD_AS, ROLLOUT_FIELDS

    assert list(HELD_AS) == list(ROLLOUT_FIELDS) and set(HELD_AS.values()) == set(LaryngoscopeTensors._STATE)


STATE_CASES = {
    "ideal, creep state": ("SoftSphereViscoelastic-v0", 20, 0.0, "z"),
    "laryngoscope, blade pose": ("SoftSphereHaptic-v0", 30, 0.6, "device.blade"),
    "laryngoscope, hand pose": ("SoftSphereHaptic-v0", 30, 0.6, "device.hand"),
}


@pytest.mark.parametrize("case", STATE_CASES, ids=list(STATE_CASES))
def test_start_state_gradients_match_central_differences(case):
    """``track_state()`` after ``reset()``: the episode's summed reward has gradients to the start state, which
    agree with central differences of the start state moved in place (as track_state's docstring offers)."""
    env_id, steps, press, name = STATE_CASES[case]
    actions = _actions(steps, 2, 4, press)
    env = gym.make_vec(f"softenv:{env_id}", num_envs=2, vectorization_mode="vector_entry_point", backend="torch",
                       differentiable=True)

    def episode(moved: tuple[tuple[int, int], float] | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        env.reset(seed=0)
        state = env.unwrapped.track_state()
        if moved is not None:
            with torch.no_grad():
                state[name][moved[0]] += moved[1]
        return torch.stack([env.step(a)[1] for a in actions]).sum(), state[name]

    total, leaf = episode()
    total.backward()
    grad = leaf.grad.clone()
    assert grad.abs().sum() > 0
    scale = grad.abs().max().item()
    rng = np.random.default_rng(5)
    for _ in range(3):
        i = (int(rng.integers(2)), int(rng.integers(grad.shape[1])))
        with torch.no_grad():
            fd = (episode((i, 1e-6))[0] - episode((i, -1e-6))[0]) / 2e-6
        assert abs(grad[i].item() - fd.item()) <= RELATIVE_BOUND * scale + 1e-9, (i, grad[i].item(), fd.item())


def test_track_state_refuses_a_plain_twin_and_a_twin_not_yet_reset():
    plain = gym.make_vec("softenv:SoftSphere-v0", num_envs=2, vectorization_mode="vector_entry_point", backend="torch")
    plain.reset(seed=0)
    with pytest.raises(ValueError, match="track_state\\(\\) needs differentiable=True"):
        plain.unwrapped.track_state()
    fresh = gym.make_vec("softenv:SoftSphere-v0", num_envs=2, vectorization_mode="vector_entry_point", backend="torch",
                         differentiable=True)
    with pytest.raises(RuntimeError, match="call reset\\(\\) before track_state\\(\\)"):
        fresh.unwrapped.track_state()


PARAM_CASES = {
    "ideal, stiffness, reach": ("SoftSphere-v0", 20, "tissue_stiffness", {}),
    "ideal, stiffness, stiffening law, creep": ("SoftSphereViscoelastic-v0", 20, "tissue_stiffness",
                                                {"tissue": {"law": "stiffening"}}),
    "ideal, target, procedure": ("SoftSphereProcedure-v0", 20, "target_shift", {}),
    "laryngoscope, target": ("SoftSphereHaptic-v0", 30, "target_shift", {}),
    "laryngoscope, tongue stiffness": ("SoftSphereHaptic-v0", 30, "tissue_stiffness", {}),
    "laryngoscope, coupling stiffness": ("SoftSphereHaptic-v0", 30, "coupling_stiffness", {}),
    "laryngoscope, coupling damping": ("SoftSphereHaptic-v0", 30, "coupling_damping", {}),
    "laryngoscope, wrist stiffness": ("SoftSphereHaptic-v0", 30, "rotational_stiffness", {}),
    "laryngoscope, wrist damping": ("SoftSphereHaptic-v0", 30, "rotational_damping", {}),
    "ideal, stiffening depth, stiffening law": ("SoftSphere-v0", 20, "stiffening_depth", {"tissue": {"law": "stiffening"}}),
    "laryngoscope, stiffening depth, stiffening law": ("SoftSphereHaptic-v0", 30, "stiffening_depth",
                                                       {"tissue": {"law": "stiffening"}}),
}
# where the differences are taken: a stiffer tongue keeps its forces in the table
PARAM_BASE = {"tissue_stiffness": 1.3, "target_shift": 0.0, "coupling_stiffness": 0.9, "coupling_damping": 1.2,
              "rotational_stiffness": 1.1, "rotational_damping": 0.8, "stiffening_depth": 1.1}
# at the scene's own depth: at 1.1 central differences at steps 1e-4 ... 1e-7 disagree with each other (a
# kink within reach), the finest agreeing with the gradient to 1e-8
CASE_BASE = {"laryngoscope, stiffening depth, stiffening law": 1.0}


@pytest.mark.parametrize("case", PARAM_CASES, ids=list(PARAM_CASES))
def test_scene_parameter_gradients_match_central_differences(case):
    """``track_params()``: at their start values the step is the plain twin's bit for bit; the episode's summed
    reward has gradients to the scene parameters, which agree with central differences of a parameter moved
    in place (as track_params' docstring offers)."""
    env_id, steps, name, scene = PARAM_CASES[case]
    actions = _actions(steps, 2, 6, 0.6 if "Haptic" in env_id else 0.0)
    plain, _ = _rollout(env_id, actions, False, **scene)
    env = gym.make_vec(f"softenv:{env_id}", num_envs=2, vectorization_mode="vector_entry_point", backend="torch",
                       differentiable=True, **scene)
    params = env.unwrapped.track_params()
    env.reset(seed=0)
    assert torch.equal(torch.stack([env.step(a)[1] for a in actions]).detach(), plain)
    leaf, base = params[name], CASE_BASE.get(case, PARAM_BASE[name])

    def episode(moved: tuple[tuple[int, ...], float] | None = None) -> torch.Tensor:
        with torch.no_grad():
            leaf.fill_(base)
            if moved is not None:
                leaf[moved[0]] += moved[1]
        env.reset(seed=0)
        return torch.stack([env.step(a)[1] for a in actions]).sum()

    leaf.grad = None
    episode().backward()
    grad = leaf.grad.clone()
    assert grad.abs().sum() > 0
    scale = grad.abs().max().item()
    rng = np.random.default_rng(7)
    for _ in range(3):
        i = tuple(int(rng.integers(d)) for d in grad.shape)
        with torch.no_grad():
            fd = (episode((i, 1e-6)) - episode((i, -1e-6))) / 2e-6
        assert abs(grad[i].item() - fd.item()) <= RELATIVE_BOUND * scale + 1e-9, (i, grad[i].item(), fd.item())


@pytest.mark.parametrize("law", ["linear", "stiffening"])
def test_a_tongue_s_times_as_stiff_deforms_under_a_force_as_the_scenes_under_that_force_over_s(law):
    """What ``tissue_stiffness`` rests on, checked on the analytic tissue itself (saturation included: the
    largest load indents beyond its linear share)."""
    mesh = latlong_mesh(12)
    rng = np.random.default_rng(3)
    contacts = rng.normal(size=(6, 3))
    contacts = 0.03 * contacts / np.linalg.norm(contacts, axis=1, keepdims=True)
    forces = rng.normal(size=(6, 3)) * 20.0 - 40.0 * contacts / 0.03
    forces[0] = -3000.0 * contacts[0] / 0.03           # one load deep in saturation (either law)
    base = TissueParams(law=law)
    for s in (0.7, 1.6):
        stiff = AnalyticTissue(mesh, TissueParams(law=law, E=base.E * s)).displacements(contacts, forces)
        scaled = AnalyticTissue(mesh, base).displacements(contacts, forces / s)
        np.testing.assert_allclose(stiff, scaled, rtol=1e-12, atol=1e-15)
    assert AnalyticTissue(mesh, base).amplitudes(contacts, forces / 0.7)["normal_saturation"].min() < 1.0


def test_track_params_refuses_a_plain_twin_a_parameter_the_device_lacks_and_a_modulus_not_above_0_and_names_each_devices():
    plain = gym.make_vec("softenv:SoftSphere-v0", num_envs=2, vectorization_mode="vector_entry_point", backend="torch")
    with pytest.raises(ValueError, match="track_params\\(\\) needs differentiable=True"):
        plain.unwrapped.track_params()
    haptic = gym.make_vec("softenv:SoftSphereHaptic-v0", num_envs=2, vectorization_mode="vector_entry_point",
                          backend="torch", differentiable=True)
    assert list(haptic.unwrapped.track_params()) == ["target_shift", "coupling_stiffness", "coupling_damping",
                                                     "tissue_stiffness", "rotational_stiffness", "rotational_damping"]
    env = gym.make_vec("softenv:SoftSphere-v0", num_envs=2, vectorization_mode="vector_entry_point", backend="torch",
                       differentiable=True)
    with pytest.raises(ValueError, match="names contains 'coupling_stiffness': on device.kind='ideal' the scene "
                                         "parameters are \\['target_shift', 'tissue_stiffness'\\]"):
        env.unwrapped.track_params(("coupling_stiffness",))
    stiffness = env.unwrapped.track_params(("tissue_stiffness",))["tissue_stiffness"]
    env.reset(seed=0)
    with torch.no_grad():
        stiffness[1] = 0.0
    with pytest.raises(ValueError, match="tissue_stiffness\\[1\\] = 0.0: a modulus factor must be > 0"):
        env.step(torch.zeros(2, 4, dtype=torch.float64))


def test_the_depth_sensitivity_is_the_analytic_tissues_derivative_and_its_first_order_model_bias_is_second_order():
    """``stiffening_depth``'s table against the tissue itself at the table's nodes: central differences at
    ten times the table's step agree to 1e-6 of its scale; and the first-order model's error against the
    tissue at a depth 5 % and 10 % off is second order (it quarters when the offset halves, within 10 %)."""
    env = gym.make("softenv:SoftSphere-v0", tissue={"law": "stiffening"})
    scene = env.unwrapped.world.scene
    sensitivity, table = depth_sensitivity(scene), scene.response
    rng = np.random.default_rng(5)
    nodes = np.array(table.nodes)
    at = rng.integers(0, nodes, size=(40, 4))
    x = table.low_ + at * (table.high_ - table.low_) / (nodes - 1)

    def exact(q: float) -> np.ndarray:
        tissue = AnalyticTissue(scene.mesh, replace(scene.tissue, stiffening_depth=scene.tissue.stiffening_depth * q))
        return ExactResponse(tissue, scene.layout, scene.shape_model).predict(x)

    step = 10 * DEPTH_STEP
    truth = (exact(1 + step) - exact(1 - step)) / (2 * step)
    found = sensitivity.predict(x)
    assert np.abs(truth).max() > 1e-4                        # the depth moves the shapes
    np.testing.assert_allclose(found, truth, atol=1e-6 * np.abs(truth).max())
    base = exact(1.0)
    errors = [np.abs(exact(1 + d) - (base + d * found)).max() for d in (0.1, 0.05)]
    assert 3.6 < errors[0] / errors[1] < 4.4, errors


def test_the_contact_law_s_depth_derivative_is_the_tissue_s_and_its_first_order_model_bias_is_second_order():
    """The laryngoscope's side of ``stiffening_depth``: the load table's derivative against the tissue's own,
    ``dP/dq = -(dW/dq) / (dW/dP)`` at the table's nodes (the indentation ``W`` of the analytic tissue
    differenced at a fixed load, no table between), to 1e-3 of its scale (the table's central differences
    read the curve's interpolant); and the first-order law's error against the law rebuilt at a depth 5 %
    and 10 % off is second order (it quarters when the offset halves, within 10 %)."""
    env = gym.make("softenv:SoftSphereHaptic-v0", tissue={"law": "stiffening"})
    world = env.unwrapped.world
    scene, force = world.scene, world.config["device"]["max_normal_force"]
    tissue, radius = scene.tissue, scene.tissue.radius
    contact = TongueContact(scene.contact_curve(force), friction=0.3)
    loads, slopes = depth_derivative(contact, tissue, scene.mesh, force)

    def indentation(P: np.ndarray, q: float) -> np.ndarray:
        at = AnalyticTissue(scene.mesh, replace(tissue, stiffening_depth=tissue.stiffening_depth * q))
        forces = np.zeros((P.size, 3))
        forces[:, 2] = -P
        return at.amplitudes(np.tile([0.0, 0.0, radius], (P.size, 1)), forces)["indentation"]

    nodes = np.arange(TABLE_INTERVALS + 1) * contact.step
    at = np.flatnonzero((nodes > 0) & (nodes <= 1.5 * contact.curve.design_depth))[::50]
    P, h = contact.loads[at], 1e-5
    truth = -((indentation(P, 1 + h) - indentation(P, 1 - h)) / (2 * h)) / \
        ((indentation(P * (1 + h), 1.0) - indentation(P * (1 - h), 1.0)) / (2 * h * P))
    assert np.abs(truth).max() > 1.0                          # the depth moves the law (N a unit of q)
    np.testing.assert_allclose(loads[at], truth, atol=1e-3 * np.abs(truth).max())
    depths = np.linspace(0.0, 1.5 * contact.curve.design_depth, 400)
    i = np.minimum(depths * contact.inv_step, contact.top).astype(np.int64)
    errors = []
    for d in (0.1, 0.05):
        first = contact.loads[i] + d * loads[i] + (depths - i * contact.step) * (contact.slopes[i] + d * slopes[i])
        rebuilt = TongueContact(analytic_curve(replace(tissue, stiffening_depth=tissue.stiffening_depth * (1 + d)),
                                               scene.mesh, force), friction=0.3)
        errors.append(np.abs(rebuilt.load(depths) - first).max())
    assert 3.6 < errors[0] / errors[1] < 4.4, errors


def test_only_an_analytic_stiffening_tongue_has_a_depth():
    linear = gym.make_vec("softenv:SoftSphere-v0", num_envs=2, vectorization_mode="vector_entry_point", backend="torch",
                          differentiable=True)
    assert "stiffening_depth" not in linear.unwrapped.scene_params()
    stiffening = gym.make_vec("softenv:SoftSphere-v0", num_envs=2, vectorization_mode="vector_entry_point",
                              backend="torch", differentiable=True, tissue={"law": "stiffening"})
    depth = stiffening.unwrapped.track_params(("stiffening_depth",))["stiffening_depth"]
    stiffening.reset(seed=0)
    with torch.no_grad():
        depth[0] = -1.0
    with pytest.raises(ValueError, match="stiffening_depth\\[0\\] = -1.0: a depth factor must be > 0"):
        stiffening.step(torch.zeros(2, 4, dtype=torch.float64))
    with pytest.raises(ValueError, match="the stiffening depth is a parameter of the analytic tongue's stiffening law"):
        depth_sensitivity(linear.unwrapped.world.scene)
    for law, offered in (("linear", False), ("stiffening", True)):    # the laryngoscope's contact law takes it too
        haptic = gym.make_vec("softenv:SoftSphereHaptic-v0", num_envs=2, vectorization_mode="vector_entry_point",
                              backend="torch", differentiable=True, tissue={"law": law})
        assert haptic.unwrapped.scene_params().count("stiffening_depth") == int(offered)
