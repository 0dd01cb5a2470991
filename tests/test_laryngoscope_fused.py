"""The laryngoscope's fused engine (softenv.devices.laryngoscope.fused: a control period as one Triton
kernel) against the Warp kernel in Triton's interpreter on CPU (on a GPU, to a bound:
tests/test_torch_laryngoscope.py); and the engine the torch twin picks."""

import functools
import importlib.util
import json
import os
import subprocess
import sys
import textwrap

import gymnasium as gym
import pytest

torch = pytest.importorskip("torch")

from lever_support import lever_actions  # noqa: E402
from softenv.devices.laryngoscope.part import laryngoscope_parts  # noqa: E402
from softenv.devices.laryngoscope.part_tensors import tensor_engine  # noqa: E402
from softenv.devices.laryngoscope.single import Laryngoscope  # noqa: E402
from softenv.devices.laryngoscope.warp_tensors import LaryngoscopeWarpTensors  # noqa: E402
from softenv.envs import HAPTIC_SCENES  # noqa: E402
from softenv.envs.config import scene_config  # noqa: E402
from softenv.envs.world import World  # noqa: E402

HAS_TRITON = importlib.util.find_spec("triton") is not None

# Periods of a rollout of the numpy engine, each stepped again by the fused kernel from the state before
# it: the kernel's engine keeps no contact state across periods, so the state and the action fix the period.
INTERPRETED = textwrap.dedent("""
    import json, sys
    import numpy as np, torch
    from softenv.devices.laryngoscope.fused import LaryngoscopeFused
    from softenv.devices.laryngoscope.part import laryngoscope_parts
    from softenv._ops import ScalarOps
    from softenv.devices.laryngoscope.physics import hand_command, jaw_force
    from softenv.devices.laryngoscope.warp_arrays import LaryngoscopeWarp
    from softenv.envs import HAPTIC_SCENES
    from softenv.envs.config import scene_config
    from softenv.envs.world import World

    world = World(scene_config(HAPTIC_SCENES["SoftSphereHaptic-v0"], json.loads(sys.argv[1])))
    parts = laryngoscope_parts(world.scene, world.config)
    n = 4
    actions = np.random.default_rng(4).uniform(-1, 1, (100, n, 4))
    actions[:24, :, 1] = np.abs(actions[:24, :, 1])          # pressing the tongue
    actions[24:72, :2] = [1.0, 0.0, 0.0, 1.0]                  # two devices inserting, levering on the incisors
    actions[:, 2:] = np.array(json.loads(sys.argv[2]))[:, None]  # two levered to 30 N on them, then held
    ref, fused = LaryngoscopeWarp(*parts, n), LaryngoscopeFused(*parts, n)
    rollout = []
    for a in actions:
        before = ref.state()
        ref.control_step(a)
        rollout.append((before, a, ref.state(), ref.incisor_force.copy()))
    levering = [k for k, r in enumerate(rollout) if (r[3] > 0).any()]
    tongue = [k for k, r in enumerate(rollout) if (r[2].contact[:, 0] > 0).any() and k not in levering]
    hardest = max(levering, key=lambda k: rollout[k][3].max())          # the blade deepest into the incisors
    # levered on the incisors, the tongue pressed where the barrier predicts the teeth's push
    levered = [k for k, r in enumerate(rollout) if (r[3][2:] > 0).all() and (r[2].contact[2:, 0] > 25).all()]
    # on an airway with lower incisors: the periods ending with blades pressing the jaw
    jawed = [k for k, r in enumerate(rollout) if ref.c.jaw is not None and any(
        jaw_force((b[0], b[1], b[2], np.cos(b[2]), np.sin(b[2]), *b[3:]), ref.c, ScalarOps)[1] != 0 for b in r[2].blade)]
    worst = {}
    for k in sorted({tongue[0], levering[0], hardest, levering[-1], levered[0], len(rollout) - 1, *jawed[:1], *jawed[-1:]}):
        before, a, after, _ = rollout[k]
        fused.load_state(before)
        # the hand's command as the Warp kernel makes it (the C library's cos and sin): the kernels' own arithmetic
        command = hand_command(a.T, before.hand[:, 2], ref.params, type("Host", (), {"cos": np.cos, "sin": np.sin}))
        fused.substeps(*(torch.as_tensor(np.asarray(c, dtype=np.float64)) for c in command), ref.n_substeps)
        state = fused.state()
        for field in ("blade", "hand", "lateral", "contact", "hand_velocity"):
            x, y = getattr(after, field), getattr(state, field)
            scale = max(float(np.abs(x).max()), 1e-300)
            worst[field] = max(worst.get(field, 0.0), float(np.abs(x - y).max()) / scale)
    levering, tongue, levered, jawed = len(levering), len(tongue), len(levered), len(jawed)
    print(json.dumps({"worst": worst, "levering": levering, "tongue": tongue, "levered": levered, "jawed": jawed}))
""")


# the default scene, softenv bench's light blade driven fast, which sinks it into the incisors until their
# cores overlap (tests/test_laryngoscope_arrays.py): the collision's other branch; and an airway with lower
# incisors 1 mm under the blade (the jaw's spring)
CORNERS = {"default": {}, "fast": {"device": {"max_hand_speed": 5.0, "blade_mass": 0.01, "coupling_damping": 150.0}},
           "jaw": {"airway": {"interincisal_gap": 26.0}}}


@pytest.mark.slow
@pytest.mark.skipif(not HAS_TRITON, reason="needs triton, which comes with torch's CUDA builds (or pip install triton)")
@pytest.mark.parametrize("corner", CORNERS)
def test_the_fused_kernel_steps_as_the_warp_kernel_in_the_interpreter(corner):
    """Triton's interpreter runs the kernel on CPU with numpy's operations, from the Warp kernel's state
    before a period with the Warp kernel's hand command: periods pressing the tongue, the first and last
    levering on the incisors, the one bearing hardest on them (the fast corner's blade sinks into them),
    the first with two blades levered on them and pressing the tongue past 25 N, and the last (those two
    held there), and on the airway with lower incisors the first and last pressing the jaw; the state within 1e-12 of each field's largest value (numpy's exp, which the interpreter
    calls, may differ from the C library's in the last bit)."""
    world = World(scene_config(HAPTIC_SCENES["SoftSphereHaptic-v0"], CORNERS[corner]))
    lever = lever_actions(Laryngoscope(*laryngoscope_parts(world.scene, world.config)), 30.0, 80, 20)
    run = subprocess.run([sys.executable, "-c", INTERPRETED, json.dumps(CORNERS[corner]), json.dumps(lever)],
                         env={**os.environ, "TRITON_INTERPRET": "1"}, capture_output=True, text=True, timeout=900)
    assert run.returncode == 0, run.stderr[-3000:]
    checked = json.loads(run.stdout.strip().splitlines()[-1])
    assert checked["levering"] >= 3 and checked["tongue"] >= 3 and checked["levered"] >= 10, checked
    assert (checked["jawed"] >= 10) == (corner == "jaw"), checked
    assert max(checked["worst"].values()) <= 1e-12, checked


@pytest.mark.slow
@pytest.mark.skipif(not HAS_TRITON, reason="needs triton, which comes with torch's CUDA builds (or pip install triton)")
def test_the_fused_kernel_compiles_for_hopper_without_a_gpu(tmp_path):
    """Triton compiles the kernel for sm_90 (H100, H200) through a first launch's own path (the engine's
    arguments bound and specialised; nothing launched), and ptxas (shipped with Triton) assembles it: what
    Triton would refuse on the GPU (a loop-carried value changing type, a constant it cannot type) fails here. One thread a device shares
    nothing with another, so the kernel uses no shared memory; its loops are the substeps and, inside them,
    the solver's iterations."""
    script = os.path.join(os.path.dirname(__file__), "..", "scripts", "fused_kernel_profile.py")
    run = subprocess.run([sys.executable, script, "--out", str(tmp_path)], capture_output=True, text=True,
                         timeout=900)
    assert run.returncode == 0, run.stderr[-3000:]
    report = json.loads((tmp_path / "fused_kernel_sm90.json").read_text())
    assert report["shared_bytes"] == 0, report
    assert 0 < report["registers"] <= 255, report
    roles = [x["role"] for x in report["loops"]]
    assert roles.count("substeps") == 1 and roles.count("solver iterations") == 1, roles
    solver = report["loops"][roles.index("solver iterations")]
    assert 0 < solver["fp64"] < report["loops"][roles.index("substeps")]["fp64"], report
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fused_kernel_sm90.json", "fused_kernel_sm90.md"]


def test_the_torch_twin_picks_the_engine_batch_engine_and_the_device_name():
    """``auto`` (the default) is the Triton kernel on CUDA where triton is, the Warp kernel elsewhere;
    ``warp`` the Warp kernel on any device; ``triton`` on CPU tensors and ``pymunk`` are refused by name,
    also through gym.make_vec; so are the retired names."""
    cpu = torch.device("cpu")
    assert tensor_engine("auto", cpu) is LaryngoscopeWarpTensors and tensor_engine("warp", cpu) is LaryngoscopeWarpTensors
    if HAS_TRITON and torch.cuda.is_available():
        assert tensor_engine("auto", torch.device("cuda")).__name__ == "LaryngoscopeFused"
        assert tensor_engine("warp", torch.device("cuda")) is LaryngoscopeWarpTensors
    with pytest.raises(ValueError, match=r"device.batch_engine='triton' with torch_device='cpu': Triton steps CUDA"):
        tensor_engine("triton", cpu)
    make = functools.partial(gym.make_vec, "softenv:SoftSphereHaptic-v0", num_envs=2,
                             vectorization_mode="vector_entry_point", backend="torch")
    with pytest.raises(ValueError, match=r"device.batch_engine='pymunk' has no torch engine"):
        make(device={"batch_engine": "pymunk"})
    with pytest.raises(ValueError, match=r"device.batch_engine='numpy' is retired"):
        make(device={"batch_engine": "numpy"})


@pytest.mark.skipif(not (HAS_TRITON and torch.cuda.is_available()), reason="the fused engine runs on CUDA devices")
@pytest.mark.parametrize("cuda_graph", [False, True], ids=["compiled", "compiled-and-recorded"])
def test_compile_options_compile_the_env_around_the_fused_kernel(cuda_graph):
    """The kernel is compiled already, so ``compile_options`` compiles the env's work around it (inductor's
    code for the response lookup, the reward, the episodes' starts; tests/test_torch_laryngoscope.py has
    the graphs) and the kernel runs as it is: through autoresets the step agrees with the eager env's to
    rounding, recorded as CUDA graphs or not."""
    torch._dynamo.reset()
    kwargs = dict(num_envs=64, torch_device="cuda", target_draw="device", check_actions=False, max_episode_steps=6,
                  autoreset_mode="same_step")
    make = functools.partial(gym.make_vec, "softenv:SoftSphereHaptic-v0", vectorization_mode="vector_entry_point",
                             backend="torch", **kwargs)
    eager, compiled = make(), make(compile_options={}, cuda_graph=cuda_graph)
    assert type(compiled.unwrapped._device.laryngoscopes).__name__ == "LaryngoscopeFused"
    eager.reset(seed=3)
    compiled.reset(seed=3)
    generator = torch.Generator(device="cuda").manual_seed(0)
    for _ in range(20):
        a = torch.rand((64, 4), generator=generator, device="cuda", dtype=torch.float64) * 2 - 1
        o1, r1, te1, tr1, i1 = eager.step(a)
        o2, r2, te2, tr2, i2 = compiled.step(a)
        torch.testing.assert_close(o2, o1, rtol=0, atol=1e-6)              # float32 observations
        torch.testing.assert_close(r2, r1, rtol=0, atol=1e-9)
        torch.testing.assert_close(i2["incisor_force_N"], i1["incisor_force_N"], rtol=0, atol=1e-9)
        assert torch.equal(te1 | tr1, te2 | tr2)
    torch._dynamo.reset()
