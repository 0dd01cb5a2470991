"""The laryngoscope's engines on torch tensors (the Warp kernel's, softenv.devices.laryngoscope.warp_tensors;
the Triton kernel's on CUDA, .fused) against the numpy twin's Warp engine, which equals the single pymunk
device bit for bit (tests/test_laryngoscope_warp.py), and the torch twin on the haptic ids against the
numpy twin."""

import importlib.util

import gymnasium as gym
import numpy as np
import pytest

torch = pytest.importorskip("torch")

from softenv.devices.laryngoscope.part import laryngoscope_parts  # noqa: E402
from softenv.devices.laryngoscope.warp_arrays import LaryngoscopeWarp  # noqa: E402
from softenv.devices.laryngoscope.warp_tensors import LaryngoscopeWarpTensors  # noqa: E402
from softenv.envs import HAPTIC_SCENES  # noqa: E402
from softenv.envs.config import scene_config  # noqa: E402
from softenv.envs.world import World  # noqa: E402

DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
# the Warp kernel on every device; the fused Triton kernel (the torch twin's default on CUDA) on CUDA
ENGINES = [("warp", d) for d in DEVICES] + \
    ([("fused", "cuda")] if "cuda" in DEVICES and importlib.util.find_spec("triton") is not None else [])


def _engine(name):
    if name == "fused":
        from softenv.devices.laryngoscope.fused import LaryngoscopeFused      # triton: GPU machines only

        return LaryngoscopeFused
    return LaryngoscopeWarpTensors
FIELDS = ("blade", "hand", "lateral", "contact", "hand_velocity")


def _rollout_actions(periods, n, seed=4):
    """Pressing, then two devices inserting and levering on the incisors (into the walls), idling, random."""
    actions = np.random.default_rng(seed).uniform(-1, 1, (periods, n, 4))
    part = max(periods // 8, 1)
    actions[:2 * part, :, 1] = np.abs(actions[:2 * part, :, 1])
    actions[2 * part:6 * part, :2] = [1.0, 0.0, 0.0, 1.0]
    actions[6 * part:6 * part + part // 2] = 0.0
    return actions


@pytest.mark.parametrize("engine, device", ENGINES, ids=[f"{e}-{d}" for e, d in ENGINES])
@pytest.mark.parametrize("sections, periods, on_incisors", [
    ({}, 100, 5),
    ({"device": {"coupling_stiffness": 1e6, "blade_mass": 0.01, "handle_mass": 0.0}, "tissue": {"E": 1e7}}, 1, 0),
    ({"tissue": {"E": 1e3}}, 40, 0),
], ids=["default", "stiff", "soft"])
def test_the_tensor_batch_agrees_with_the_numpy_engine_over_whole_rollouts(sections, periods, on_incisors, engine,
                                                                          device):
    """Every control period of a rollout (pressing, levering on the incisors and into the walls, idle,
    random) on the default scene and the documented extreme corners (1e6 N/m coupling, 10 g blade, 10 MPa
    tongue: one period of its 1,826 substeps; a 1 kPa tongue): on CPU the Warp kernel equals the numpy
    twin's bit for bit; on a GPU (whose cos, sin and exp are not the C library's, and where the fused
    kernel takes the hand's command from torch's) the blade's pose within 1e-9 (m, rad), the hands
    exactly, the lateral state, the tongue's and incisors' forces and the observation within 1e-5 of their
    largest value in the rollout (the lateral stick-slip switches on a comparison, so rounding grows there)."""
    world = World(scene_config(HAPTIC_SCENES["SoftSphereHaptic-v0"], sections))
    parts = laryngoscope_parts(world.scene, world.config)
    n = 4
    ref, mine = LaryngoscopeWarp(*parts, n), _engine(engine)(*parts, n, device)
    exact = device == "cpu"
    peaks = {f: 1e-300 for f in FIELDS}
    incisors = 0
    for a in _rollout_actions(periods, n):
        ref.control_step(a)
        mine.control_step(torch.as_tensor(a, device=device))
        s, t = ref.state(), mine.state()
        for f in FIELDS:
            x, y = getattr(s, f), getattr(t, f)
            peaks[f] = max(peaks[f], float(np.abs(x).max()))
            tol = 0.0 if exact else 1e-9 if f == "blade" else 1e-5 * peaks[f]
            assert np.abs(x - y).max() <= tol, (f, np.abs(x - y).max(), tol)
        np.testing.assert_allclose(mine.observation().cpu().numpy(), ref.observation(), rtol=0, atol=0 if exact else 1e-5)
        incisors += int(np.count_nonzero(ref.incisor_force > 0))
    assert incisors >= on_incisors
    assert mine.observation().device.type == device


def _make(env_id, backend, **kwargs):
    extra = {"backend": "torch", "dtype": kwargs.pop("dtype", torch.float64)} if backend == "torch" else {}
    return gym.make_vec(f"softenv:{env_id}", vectorization_mode="vector_entry_point", **extra, **kwargs)


@pytest.mark.parametrize("env_id,mode,obs_mode", [("SoftSphereHaptic-v0", "next_step", "vector"),
                                                  ("SoftSphereHapticProcedure-v0", "same_step", "dict")])
def test_the_torch_twin_steps_the_haptic_ids_as_the_numpy_twin(env_id, mode, obs_mode):
    """float64 on CPU tensors against the numpy twin, the same seeds and actions (pressing into the tongue,
    inserting and levering, random) through autoresets: observations within float32 rounding, rewards
    and every info (the device's among them: incisor, tongue and haptic force, blade pose) within 1e-6 of
    their scale, the same flags. (The incisors' contact itself: the test above.)"""
    n = 3
    ref = _make(env_id, "numpy", num_envs=n, autoreset_mode=mode, obs_mode=obs_mode, max_episode_steps=25)
    env = _make(env_id, "torch", num_envs=n, autoreset_mode=mode, obs_mode=obs_mode, max_episode_steps=25)
    obs_ref, _ = ref.reset(seed=11)
    obs, _ = env.reset(seed=11)
    actions = _rollout_actions(60, n, seed=5).astype(np.float32)
    resets = 0
    for a in actions:
        pairs = [(obs_ref, obs)] if obs_mode == "vector" else [(obs_ref[k], obs[k]) for k in obs_ref]
        for x, y in pairs:
            np.testing.assert_allclose(y.numpy(), x, rtol=1e-5, atol=1e-5)
        obs_ref, r_ref, te_ref, tr_ref, info_ref = ref.step(a)
        obs, r, te, tr, info = env.step(torch.as_tensor(a))
        np.testing.assert_allclose(r.numpy(), r_ref, rtol=1e-6, atol=1e-6)
        assert np.array_equal(te_ref, te.numpy()) and np.array_equal(tr_ref, tr.numpy())
        stepped = info_ref.get("_normalized_score", np.zeros(n, dtype=bool))      # none on an all-reset step
        assert np.array_equal(info["_normalized_score"].numpy(), stepped)
        for key in ("reward_incisor", "incisor_force_N", "tongue_force_N", "haptic_force_N", "blade_pose",
                    "normalized_score", "force_N"):
            if stepped.any():
                x, y = np.asarray(info_ref[key], dtype=np.float64)[stepped], info[key].numpy()[stepped]
                np.testing.assert_allclose(y, x, rtol=1e-6, atol=1e-6 * max(1.0, float(np.abs(x).max())))
        resets += int(np.sum(te_ref | tr_ref))
    assert resets >= 2 * n


@pytest.mark.parametrize("device", DEVICES)
def test_float32_tensors_keep_the_device_in_float64_and_stay_near_it(device):
    """A float32 env keeps the laryngoscope's physics in float64 (its contact spans five decades of
    stiffness) and returns float32 tensors on its device within 1e-4 of the float64 env."""
    e64 = _make("SoftSphereHaptic-v0", "torch", num_envs=4)
    e32 = _make("SoftSphereHaptic-v0", "torch", num_envs=4, dtype=torch.float32, torch_device=device)
    e64.reset(seed=0)
    e32.reset(seed=0)
    assert e32.unwrapped._device.laryngoscopes._blade.dtype == torch.float64
    for a in torch.as_tensor(_rollout_actions(25, 4, seed=2), dtype=torch.float32):
        o64, r64, _, _, i64 = e64.step(a)
        o32, r32, _, _, i32 = e32.step(a.to(device))
        assert r32.dtype == torch.float32 and r32.device.type == device and o32.device.type == device
        np.testing.assert_allclose(r32.cpu().numpy(), r64.numpy(), rtol=1e-4, atol=1e-4)
        np.testing.assert_allclose(o32.cpu().numpy(), o64.numpy(), rtol=0, atol=1e-4)


def _state_tensors(env):
    """Every tensor of the laryngoscopes' state that a step reads from the last one, by name."""
    dev = env.unwrapped._device.laryngoscopes
    return {name: getattr(dev, name) for name in dev._STATE}


def test_the_tensor_state_stays_where_the_last_step_wrote_it():
    """What a CUDA graph of the step needs (it replays reads and writes at the addresses it recorded): every
    state tensor keeps its address through steps levering on the teeth, autoresets and reset(), while its
    values change."""
    env = _make("SoftSphereHaptic-v0", "torch", num_envs=4, target_draw="device", check_actions=False,
                max_episode_steps=30, autoreset_mode="same_step")
    env.reset(seed=0)
    actions = torch.as_tensor(_rollout_actions(70, 4, seed=3))
    env.step(actions[0])
    before = {name: (t.data_ptr(), t.clone()) for name, t in _state_tensors(env).items()}
    assert len(before) == 6
    for a in actions[1:]:
        env.step(a)
    env.reset(seed=1)
    env.step(actions[1])
    after = _state_tensors(env)
    assert {name: t.data_ptr() for name, t in after.items()} == {name: p for name, (p, _) in before.items()}
    assert not torch.equal(after["_blade"], before["_blade"][1]) and not torch.equal(after["_hand"], before["_hand"][1])


@pytest.mark.skipif(not torch.cuda.is_available(), reason="CUDA graphs need a CUDA device")
@pytest.mark.parametrize("batch_engine", ["triton"])
def test_the_recorded_haptic_step_replays_the_eager_one_bit_for_bit(batch_engine):
    """cuda_graph=True on the laryngoscope (the step recorded once per value of the host's may-start flag and
    replayed) against the eager step, the same seeds and actions, through autoresets and levering on the
    teeth: the same bits in every output."""
    kwargs = dict(num_envs=8, torch_device="cuda", dtype=torch.float32, target_draw="device", check_actions=False,
                  max_episode_steps=12, autoreset_mode="same_step", device={"batch_engine": batch_engine})
    eager, graphed = _make("SoftSphereHaptic-v0", "torch", **kwargs), _make("SoftSphereHaptic-v0", "torch",
                                                                              cuda_graph=True, **kwargs)
    eager.reset(seed=5)
    graphed.reset(seed=5)
    ends = 0
    for a in torch.as_tensor(_rollout_actions(40, 8, seed=6), dtype=torch.float32, device="cuda"):
        o1, r1, te1, tr1, i1 = eager.step(a)
        o2, r2, te2, tr2, i2 = graphed.step(a)
        for x, y in [(o1, o2), (r1, r2), (te1, te2), (tr1, tr2), (i1["incisor_force_N"], i2["incisor_force_N"])]:
            assert torch.equal(x, y)
        ends += int((te1 | tr1).sum())
    assert ends >= 8 * 3 and len(graphed.unwrapped._tensor_work.graphs) == 2


def test_compile_options_compile_the_env_around_the_laryngoscope():
    """The laryngoscope keeps its step apart (a Warp kernel on CPU, Triton's on CUDA), so the env compiles
    its own work around the device's calls: each is a graph break, run as it is. With a backend that runs
    dynamo's graphs as traced, the step equals the eager env's bit for bit through autoresets; no graph
    holds the device's code, and the env's graphs (the response lookup, the reward, the episodes' starts)
    are made; over 40 steps no more graphs are made than the first episodes made (no recompiling at
    every step)."""
    graphs = []

    def recorder(gm, example_inputs):
        graphs.append(gm)
        return gm.forward

    def sources(graph):
        lines = "".join(node.meta.get("stack_trace") or "" for node in graph.graph.nodes)
        return {name for name in ("envs/torch_twin.py", "devices/laryngoscope/") if name in lines}

    torch._dynamo.reset()
    kwargs = dict(num_envs=4, torch_device="cpu", target_draw="device", check_actions=False, max_episode_steps=6,
                  autoreset_mode="same_step")
    eager, compiled = _make("SoftSphereHaptic-v0", "torch", **kwargs), \
        _make("SoftSphereHaptic-v0", "torch", compile_options={"backend": recorder}, **kwargs)
    eager.reset(seed=2)
    compiled.reset(seed=2)
    made = []
    for a in torch.as_tensor(np.random.default_rng(8).uniform(-1, 1, (40, 4, 4))):
        o1, r1, te1, tr1, i1 = eager.step(a)
        o2, r2, te2, tr2, i2 = compiled.step(a)
        assert torch.equal(o1, o2) and torch.equal(r1, r2) and torch.equal(te1, te2) and torch.equal(tr1, tr2)
        assert torch.equal(i1["incisor_force_N"], i2["incisor_force_N"])
        made.append(len(graphs))
    assert not any("devices/laryngoscope/" in sources(g) for g in graphs)           # the device's step: apart
    assert sum(sources(g) == {"envs/torch_twin.py"} for g in graphs) >= 2          # the env's work, compiled
    assert all(len(sources(g)) == 1 for g in graphs), [sources(g) for g in graphs]
    assert made[-1] == made[13] > 0                                               # none after two episodes
    torch._dynamo.reset()


def test_a_device_without_tensors_is_refused_by_name():
    with pytest.raises(ValueError, match="cuda_graph=True needs a CUDA device; got device='cpu'"):
        _make("SoftSphereHaptic-v0", "torch", num_envs=2, target_draw="device", cuda_graph=True)
    with pytest.raises(ValueError, match="device.kind='examples.probe_device:PROBE' has no tensor form"):
        _make("SoftSphere-v0", "torch", num_envs=2, device={"kind": "examples.probe_device:PROBE"})
