"""The batched twin on torch tensors (softenv.envs.torch_twin) against the numpy twin."""

import gymnasium as gym
import numpy as np
import pytest

torch = pytest.importorskip("torch")

import softenv  # noqa: E402,F401  (registers the ids)

CASES = [("SoftSphere-v0", "next_step", "vector"), ("SoftSphereViscoelastic-v0", "same_step", "vector"),
         ("SoftSphereProcedure-v0", "same_step", "dict"), ("SoftSphere-v0", "next_step", "dict")]
# a GPU, where the process has one, next to CPU tensors (the float64 references stay on the CPU)
DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])


def _make(env_id, backend, **kwargs):
    extra = {"backend": "torch", "dtype": kwargs.pop("dtype", torch.float64)} if backend == "torch" else {}
    return gym.make_vec(env_id, vectorization_mode="vector_entry_point", **extra, **kwargs)


def _close(a, b, rtol, atol=0.0):
    a = np.asarray(a, dtype=np.float64)
    b = b.double().cpu().numpy() if isinstance(b, torch.Tensor) else np.asarray(b, dtype=np.float64)
    np.testing.assert_allclose(b, a, rtol=rtol, atol=atol)


@pytest.mark.parametrize("env_id,mode,obs_mode", CASES)
def test_float64_on_cpu_equals_the_numpy_twin_over_1000_steps(env_id, mode, obs_mode):
    """Observations (float32, one ulp), rewards, flags and every info (1e-12) over 1,000 steps of the
    same actions and seeds, through 10 autoresets of the mode under test."""
    n = 4
    ref = _make(env_id, "numpy", num_envs=n, autoreset_mode=mode, obs_mode=obs_mode)
    env = _make(env_id, "torch", num_envs=n, autoreset_mode=mode, obs_mode=obs_mode)
    obs_ref, _ = ref.reset(seed=7)
    obs, _ = env.reset(seed=7)
    actions = np.random.default_rng(0).uniform(-1, 1, (1000, n, 4)).astype(np.float32)
    resets = 0
    for a in actions:
        for x, y in ((obs_ref, obs),) if not isinstance(obs_ref, dict) else ((obs_ref[k], obs[k]) for k in obs_ref):
            _close(x, y, rtol=1e-6, atol=1e-7)
        obs_ref, r_ref, te_ref, tr_ref, info_ref = ref.step(a)
        obs, r, te, tr, info = env.step(torch.as_tensor(a))
        _close(r_ref, r, rtol=1e-12, atol=1e-12)
        assert np.array_equal(te_ref, te.numpy()) and np.array_equal(tr_ref, tr.numpy())
        resets += int(np.sum(te_ref | tr_ref))
        for key, value in info_ref.items():
            if key in ("final_obs", "final_info"):
                continue
            _close(value, info[key], rtol=1e-12, atol=1e-12)
        if "final_info" in info_ref:
            for key, value in info_ref["final_info"].items():
                _close(value, info["final_info"][key], rtol=1e-12, atol=1e-12)
            for i in np.flatnonzero(info_ref["_final_obs"]):
                last, mine = info_ref["final_obs"][i], info["final_obs"]
                for x, y in ((last, mine[i]),) if not isinstance(last, dict) else ((last[k], mine[k][i]) for k in last):
                    _close(x, y, rtol=1e-6, atol=1e-7)
    assert resets >= 10 * n * 0.9


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("env_id", ["SoftSphere-v0", "SoftSphereViscoelastic-v0", "SoftSphereProcedure-v0"])
def test_float32_stays_within_1e5_of_the_float64_reference(env_id, device):
    kwargs = {"num_envs": 8}
    e64, e32 = _make(env_id, "torch", **kwargs), _make(env_id, "torch", dtype=torch.float32, torch_device=device, **kwargs)
    e64.reset(seed=0)
    e32.reset(seed=0)
    generator = torch.Generator().manual_seed(0)
    for _ in range(300):
        a = torch.rand((8, 4), generator=generator) * 2 - 1
        o64, r64, _, _, i64 = e64.step(a)
        o32, r32, _, _, i32 = e32.step(a.to(device))
        assert r32.dtype == torch.float32 and r32.device.type == device
        _close(r64, r32, rtol=1e-5, atol=1e-5)
        for key in ("shape_error_mm", "normalized_score", "force_N"):
            _close(i64[key], i32[key], rtol=1e-5, atol=1e-5)
        _close(o64, o32, rtol=0, atol=1e-5 * float(o64.abs().max()))


@pytest.mark.parametrize("device", DEVICES)
def test_seeding_is_per_env_and_reproducible(device):
    a = torch.as_tensor(np.random.default_rng(1).uniform(-1, 1, (50, 3, 4)), dtype=torch.float32, device=device)
    runs = []
    for seeds in ([5, 6, 7], 5, [9, 6, 7]):
        env = _make("SoftSphere-v0", "torch", num_envs=3, torch_device=device)
        obs, _ = env.reset(seed=seeds)
        trace = [obs]
        for step in a:
            trace.append(env.step(step)[0])
        runs.append(torch.stack(trace))
    assert torch.equal(runs[0], runs[1])                       # seed=5 seeds env i with 5 + i
    assert torch.equal(runs[0][:, 1:], runs[2][:, 1:]) and not torch.equal(runs[0][:, 0], runs[2][:, 0])


def test_what_the_torch_backend_cannot_express_is_refused_by_name():
    with pytest.raises(ValueError, match="response.model='poly2'"):
        _make("SoftSphere-v0", "torch", num_envs=2, response={"model": "poly2"})
    with pytest.raises(ValueError, match="obs_mode='vertices'"):
        _make("SoftSphere-v0", "torch", num_envs=2, obs_mode="vertices")
    with pytest.raises(ValueError, match="backend='jax' must be 'numpy' or 'torch'"):
        gym.make_vec("SoftSphere-v0", num_envs=2, vectorization_mode="vector_entry_point", backend="jax")
    with pytest.raises(ValueError, match="dtype=torch.float16"):
        _make("SoftSphere-v0", "torch", num_envs=2, dtype=torch.float16)


def test_a_device_this_process_cannot_use_is_refused_by_name():
    # cuda:99 exists on no machine: a CPU build and a GPU build of torch both fail to allocate on it
    with pytest.raises(ValueError, match=r"torch_device='cuda:99' is not a torch device usable here \((a|no) CUDA"):
        _make("SoftSphere-v0", "torch", num_envs=2, torch_device="cuda:99")
    with pytest.raises(ValueError, match="torch_device='gpu' is not a torch device usable here"):
        _make("SoftSphere-v0", "torch", num_envs=2, torch_device="gpu")
    assert _make("SoftSphere-v0", "torch", num_envs=2, torch_device=torch.device("cpu")).torch_device == torch.device("cpu")


def test_bad_actions_are_refused_by_index_and_change_nothing():
    env = _make("SoftSphere-v0", "torch", num_envs=2)
    obs, _ = env.reset(seed=0)
    a = torch.zeros((2, 4))
    a[1, 2] = float("nan")
    with pytest.raises(ValueError, match=r"actions\[1, 2\] = nan"):
        env.step(a)
    with pytest.raises(ValueError, match=r"shape \(2, 4\)"):
        env.step(torch.zeros((3, 4)))
    # the refused steps left no trace: stepping now equals a fresh env's first step
    fresh = _make("SoftSphere-v0", "torch", num_envs=2)
    fresh.reset(seed=0)
    assert torch.equal(env.step(torch.zeros((2, 4)))[0], fresh.step(torch.zeros((2, 4)))[0])


def test_the_numpy_twin_imports_no_torch(heavy_modules_after):
    code = ("import gymnasium as gym, softenv\n"
            "env = gym.make_vec('SoftSphere-v0', num_envs=4, vectorization_mode='vector_entry_point')\n"
            "env.reset(seed=0)\nenv.step(env.action_space.sample())")
    assert "torch" not in heavy_modules_after(code)


def test_bench_reports_the_torch_twin_beside_the_numpy_twin(tmp_path):
    from softenv import bench

    rows = bench.run(True, tmp_path, ["torch"], command="softenv bench --quick --only torch", echo=lambda s: None)
    names = [r.metric for r in rows]
    assert any("numpy twin, 1024 envs" in name for name in names)
    torch_rows = [r for r in rows if r.metric.startswith("SoftSphere-v0: torch twin on cpu")]
    assert [r.metric.split(", ")[1:3] for r in torch_rows] == [["float64", "host draw"], ["float32", "host draw"],
                                                              ["float32", "device draw"]]
    haptic = [r for r in rows if r.metric.startswith("SoftSphereHaptic-v0: torch twin on cpu")]
    assert len(haptic) == 1 and "1024 envs" in haptic[0].metric              # beside the numpy twin's engine
    assert any(r.metric.startswith("SoftSphereHaptic-v0: numpy twin (warp engine)") for r in rows)
    assert all(r.value > 0 and "x the numpy twin" in r.spread for r in torch_rows + haptic)
    gpu = [r for r in rows if "GPU" in r.metric]
    assert torch.cuda.is_available() or (gpu and "not measured" in gpu[0].spread)   # with a GPU: --device cuda


def test_bench_device_cuda_measures_the_gpu_or_says_there_is_none(tmp_path):
    from softenv import bench

    run = lambda: bench.run(True, tmp_path, command="softenv bench --quick --device cuda", echo=lambda s: None,  # noqa: E731
                            device="cuda")
    if not torch.cuda.is_available():
        with pytest.raises(RuntimeError, match="--device cuda: no CUDA device"):
            run()
        return
    rows = run()
    assert (tmp_path / "perf-gpu_quick.md").exists()
    assert any(r.metric.startswith("host synchronisations") and r.ok for r in rows)
    assert sum(r.metric.startswith("SoftSphere-v0: torch twin on") for r in rows) == 2 * 5  # 2 sizes x 5 modes
    haptic = [r for r in rows if r.section == "gpu-haptic"]
    assert haptic[0].metric.startswith("SoftSphereHaptic-v0: host synchronisations") and haptic[0].ok
    # the sync check; 2 sizes x 2 engines (the fused kernel, the Warp kernel) x eager and recorded; the best
    assert len(haptic) == 1 + 2 * 2 * 2 + 1 and haptic[-1].target == ">= 50M"
    assert sum("CUDA graph" in r.metric for r in haptic) == 4 and all(r.value > 0 for r in haptic[1:])
    assert sum("fused kernel" in r.metric for r in haptic) == 4


def test_bench_device_cuda_runs_the_gpu_sections_alone(tmp_path):
    from softenv import bench

    with pytest.raises(ValueError, match=r"--only tissue gpu: --device cuda runs the GPU sections only \(gpu, gpu-haptic\)"):
        bench.run(True, tmp_path, ["tissue", "gpu"], echo=lambda s: None, device="cuda")
    assert not list(tmp_path.iterdir())                                  # refused before it measured or wrote


def test_the_gpu_rows_run_on_cpu_tensors_too():
    """The GPU section's code path (sizes, eager and compiled timings, targets, the device alone) on CPU
    tensors, so a first GPU run does not meet it untried."""
    from softenv.bench.env import device_rows, haptic_tensor_rows

    rows = device_rows("cpu", "cpu", (1024, 64), 2)
    twins = [r for r in rows if r.metric.startswith("SoftSphere-v0: torch twin on cpu")]
    assert [("torch.compile" in r.metric, "1,024 envs" in r.metric) for r in twins] == [
        (False, True), (True, True), (False, False), (True, False)]
    assert all(r.value > 0 and r.target == ">= 10M" and r.ok is (r.value >= 10e6) for r in twins[:2])
    assert all(r.target == "" and r.ok is None for r in twins[2:])
    assert rows[1].ok is None and "needs CUDA" in rows[1].spread
    haptic = haptic_tensor_rows("cpu", "cpu", (64,), 2)
    assert [r.unit for r in haptic] == ["env-steps/s", "device-steps/s"]        # no target off CUDA
    assert "warp kernel, eager" in haptic[0].metric and "64 envs" in haptic[0].metric
    assert "warp kernel alone" in haptic[1].metric and "64 devices" in haptic[1].metric
    assert all(r.section == "gpu-haptic" and r.value > 0 and r.ok is None for r in haptic), haptic


def test_the_cuda_graph_timing_runs_on_cpu_tensors_and_leaves_inductor_as_it_was():
    """The CUDA-graph rows' timing (the env's compile_options, inductor told to raise rather than skip
    CUDA graphs) runs on CPU tensors too (no graphs there), and the strict setting ends with it."""
    import torch._inductor.config as inductor_config

    from softenv.bench.env import torch_step_timing

    before = inductor_config.triton.cudagraph_or_error
    timing = torch_step_timing(64, "cpu", torch.float32, "device", "reduce-overhead", 2)
    assert timing.median > 0 and inductor_config.triton.cudagraph_or_error == before
    torch._dynamo.reset()


# -- target_draw="device": episodes drawn and scored on the device -------------------------------


def _splitmix64(seed, n):
    """The n-th output of splitmix64 from ``seed``, in Python integers (an independent implementation)."""
    mask = (1 << 64) - 1
    z = (seed + n * 0x9E3779B97F4A7C15) & mask
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & mask
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & mask
    return z ^ (z >> 31)


@pytest.mark.parametrize("device", DEVICES)
def test_the_device_generator_is_splitmix64(device):
    from softenv.envs.torch_parts import as_int64, episode_uniforms

    seeds = [0, 1, 12345, 2**63 - 1, 2**64 - 7]
    episodes = [0, 3, 2**40]
    seed = torch.tensor([as_int64(s) for s in seeds for _ in episodes], device=device)
    episode = torch.tensor([e for _ in seeds for e in episodes], device=device)
    got = episode_uniforms(seed, episode, 5).cpu().numpy()
    want = [[(_splitmix64(s, 8 * e + j) >> 11) / 2.0**53 for j in range(1, 6)] for s in seeds for e in episodes]
    assert np.array_equal(got, np.array(want))


@pytest.mark.parametrize("env_id", ["SoftSphere-v0", "SoftSphereViscoelastic-v0", "SoftSphereProcedure-v0"])
def test_a_device_drawn_episode_scores_as_the_numpy_env_given_its_target(env_id):
    """The on-device references (target shape by lookup, zero and oracle error sums, the oracle's creep)
    against the numpy twin's precomputed episode of the same target, over a whole episode."""
    n = 3
    env = _make(env_id, "torch", num_envs=n, target_draw="device", check_actions=False)
    obs, _ = env.reset(seed=11)
    world = env.unwrapped.world
    targets = (env.unwrapped._episodes.features.numpy() - world.force_box.mid) / world.force_box.half
    actions = np.random.default_rng(2).uniform(-1, 1, (world.horizon, n, 4))
    mine = [env.step(torch.as_tensor(a)) for a in actions]
    for i in range(n):
        ref = _make(env_id, "numpy", num_envs=1)
        o, _ = ref.reset(options={"target": targets[i]})
        _close(o[0], obs[i], rtol=1e-6, atol=1e-7)
        for a, (o_t, r_t, te_t, tr_t, info_t) in zip(actions, mine):
            o, r, te, tr, info = ref.step(a[i:i + 1])
            _close(r[0], r_t[i], rtol=1e-12, atol=1e-12)
            for key in ("normalized_score", "shape_error_mm", "reward_shape", "is_success"):
                _close(info[key][0], info_t[key][i], rtol=1e-12, atol=1e-12)
            assert (te[0], tr[0]) == (bool(te_t[i]), bool(tr_t[i]))
            if not tr[0]:
                _close(o[0], o_t[i], rtol=1e-6, atol=1e-7)
    assert bool(tr_t.all())


def test_device_targets_cover_the_split_are_reproducible_and_move_on_at_autoreset():
    n = 3000
    env = _make("SoftSphere-v0", "torch", num_envs=n, target_draw="device", max_episode_steps=2, check_actions=False)
    env.reset(seed=0)
    source, family = env.unwrapped._episodes, env.unwrapped.world.family
    first = source.features.numpy().copy()
    cells = family.cell_of(first)
    assert (cells.sum(axis=1) % 2 == 0).all()                     # all in the train split's checkerboard
    counts = np.unique(cells, axis=0, return_counts=True)[1]
    assert len(counts) == len(family.cells) and counts.min() > 0.5 * n / len(counts)
    # env i's episodes depend on its seed and episode number only, not on num_envs or the other envs
    small = _make("SoftSphere-v0", "torch", num_envs=2, target_draw="device")
    small.reset(seed=[7, 1])
    assert np.array_equal(small.unwrapped._episodes.features.numpy(), first[[7, 1]])
    zero = torch.zeros((n, 4), dtype=torch.float64)
    env.step(zero)
    env.step(zero)                                                # episodes end (truncated at 2 steps)
    assert np.array_equal(source.features.numpy(), first)        # next-step autoreset: not yet
    env.step(zero)
    second = source.features.numpy().copy()
    assert not np.isclose(second, first).all(axis=1).any()
    env.reset()                                                  # no seed: every env's next episode
    third = source.features.numpy()
    assert not np.isclose(third, second).all(axis=1).any()
    with pytest.raises(ValueError, match=r"seed\[0\]=-1 must be an int in \[0, 2\*\*64\) or None"):
        env.reset(seed=[-1] + [0] * (n - 1))
    with pytest.raises(ValueError, match="outside the target family"):
        env.reset(seed=5, options={"target": [2.0, 0.0, 0.0, 0.0]})
    assert np.array_equal(source.features.numpy(), third)        # the refused resets changed nothing
    assert torch.equal(source.episode, torch.full((n,), 2))
    with pytest.raises(ValueError, match="target_draw='gpu' must be 'host' or 'device'"):
        _make("SoftSphere-v0", "torch", num_envs=2, target_draw="gpu")


FORBIDDEN = {"item", "tolist", "nonzero", "__bool__", "numpy", "cpu"}   # host reads and dynamic shapes


@pytest.mark.parametrize("draw", ["host", "device"])
@pytest.mark.parametrize("mode", ["same_step", "next_step"])
def test_the_state_is_written_in_place(mode, draw):
    """A CUDA graph replays fixed addresses: every tensor the env holds must keep its storage through
    steps, autoresets (with success termination too) and reset()."""
    env = _make("SoftSphereViscoelastic-v0", "torch", num_envs=6, dtype=torch.float32, target_draw=draw,
                autoreset_mode=mode, check_actions=False, task={"terminate_on_success": True})
    twin = env.unwrapped
    parts = [twin] + ([twin._episodes] if draw == "device" else [])    # the host draw rebuilds its episodes on the host

    def storage():
        return {(id(part), name): (value, value.data_ptr()) for part in parts
                for name, value in vars(part).items() if isinstance(value, torch.Tensor)}

    env.reset(seed=0)
    before = storage()
    assert len(before) >= (10 if draw == "host" else 20)
    generator = torch.Generator().manual_seed(0)
    ended = 0
    for _ in range(2 * twin.world.horizon + 3):
        _, _, terminated, truncated, _ = env.step(torch.rand((6, 4), generator=generator) * 2 - 1)
        ended += int((terminated | truncated).sum())
    env.reset()
    after = storage()
    assert ended >= 12                        # the envs went through autoresets
    assert after.keys() == before.keys()
    moved = [name for (part, name), (value, ptr) in before.items() if after[(part, name)][0] is not value
             or after[(part, name)][1] != ptr]
    assert moved == []


@pytest.mark.parametrize("mode", ["same_step", "next_step"])
def test_compile_options_compile_two_graphs_without_int_inputs(mode):
    """``compile_options``: the env compiles its step's tensor work; the step count stays on the host, so
    no graph takes an int input (CUDA graphs record a new graph for each value of one), at most two
    graphs are made (episodes may start, or not), and they replay the eager env bit for bit, action
    check included."""
    graphs = []

    def recorder(gm, example_inputs):
        graphs.append(gm)
        return gm.forward

    def made(**kwargs):
        env = _make("SoftSphereProcedure-v0", "torch", num_envs=4, target_draw="device", autoreset_mode=mode,
                    max_episode_steps=3, dynamics={"kind": "viscoelastic"}, **kwargs)
        env.reset(seed=0)
        return env

    torch._dynamo.reset()
    compiled, eager = made(compile_options={"backend": recorder}), made()
    actions = torch.as_tensor(np.random.default_rng(0).uniform(-1, 1, (8, 4, 4)))
    for a in actions:                                       # 8 steps: two autoresets of every env
        got, want = compiled.step(a), eager.step(a)
        assert torch.equal(got[0], want[0]) and torch.equal(got[1], want[1]) and torch.equal(got[3], want[3])
        assert torch.equal(got[4]["normalized_score"], want[4]["normalized_score"])
    assert len(graphs) == 2
    inputs = [node.meta.get("example_value") for graph in graphs for node in graph.graph.nodes
              if node.op == "placeholder"]
    assert inputs and all(isinstance(value, torch.Tensor) for value in inputs)
    with pytest.raises(ValueError, match=r"actions\[1, 2\] = nan"):     # the check runs on the host, before the graph
        compiled.step(torch.tensor([[0.0] * 4, [0.0, 0.0, float("nan"), 0.0]] + [[0.0] * 4] * 2))
    torch._dynamo.reset()


def test_inductor_compiled_step_agrees_with_the_eager_env_to_rounding():
    """With inductor's generated code (compile_options={}, the default backend) the env is not bit for bit
    the eager one (its vector math rounds differently), but agrees to rounding: float64 within 1e-12 over
    episodes of the procedure with creep, both lookups (the agent's and the moving target's) included."""
    def made(**kwargs):
        env = _make("SoftSphereProcedure-v0", "torch", num_envs=8, target_draw="device", autoreset_mode="same_step",
                    max_episode_steps=10, dynamics={"kind": "viscoelastic"}, **kwargs)
        env.reset(seed=3)
        return env

    torch._dynamo.reset()
    compiled, eager = made(compile_options={}), made()
    for a in torch.as_tensor(np.random.default_rng(3).uniform(-1, 1, (25, 8, 4))):     # two autoresets
        got, want = compiled.step(a), eager.step(a)
        torch.testing.assert_close(got[0], want[0], rtol=1e-6, atol=1e-6)              # float32 observations
        torch.testing.assert_close(got[1], want[1], rtol=1e-12, atol=1e-12)
        assert torch.equal(got[2], want[2]) and torch.equal(got[3], want[3])
        torch.testing.assert_close(got[4]["normalized_score"], want[4]["normalized_score"], rtol=1e-12, atol=1e-10)
    torch._dynamo.reset()


def test_compile_options_are_checked():
    with pytest.raises(ValueError, match="compile_options=.*target_draw='device'.*'host'"):
        _make("SoftSphere-v0", "torch", num_envs=2, compile_options={"mode": "default"})
    with pytest.raises(ValueError, match="compile_options='reduce-overhead' must be a dict"):
        _make("SoftSphere-v0", "torch", num_envs=2, target_draw="device", compile_options="reduce-overhead")


def test_cuda_graph_is_checked():
    with pytest.raises(ValueError, match="cuda_graph=True needs target_draw='device' \\(got 'host'\\)"):
        _make("SoftSphere-v0", "torch", num_envs=2, cuda_graph=True)
    with pytest.raises(ValueError, match="no compile mode that makes CUDA graphs of its own .*'reduce-overhead'"):
        _make("SoftSphere-v0", "torch", num_envs=2, target_draw="device", cuda_graph=True,
              compile_options={"mode": "reduce-overhead"})
    with pytest.raises(ValueError, match="cuda_graph=True needs a CUDA device; got device='cpu'"):
        _make("SoftSphere-v0", "torch", num_envs=2, target_draw="device", cuda_graph=True)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="records CUDA graphs: needs a GPU (on CPU the env "
                    "refuses cuda_graph: test_cuda_graph_is_checked)")
@pytest.mark.parametrize("mode", ["same_step", "next_step"])
def test_cuda_graphs_recorded_by_the_env_replay_the_eager_env_bit_for_bit(mode):
    """``cuda_graph=True``: the recorded graphs run the eager step's own kernels on the live state, so
    they equal the eager env bit for bit (procedure with creep, through autoresets and a reset()); a
    step's outputs are the graph's tensors, rewritten by the next replay, in new containers."""
    def made(**kwargs):
        env = _make("SoftSphereProcedure-v0", "torch", num_envs=8, torch_device="cuda", target_draw="device",
                    autoreset_mode=mode, max_episode_steps=5, dynamics={"kind": "viscoelastic"},
                    check_actions=False, **kwargs)
        env.reset(seed=3)
        return env

    graphed, eager = made(cuda_graph=True), made()
    actions = torch.as_tensor(np.random.default_rng(3).uniform(-1, 1, (30, 8, 4)), device="cuda")
    rewards = []
    for i, a in enumerate(actions):                        # five autoresets of every env
        if i == 20:
            graphed.reset(seed=4), eager.reset(seed=4)
        got, want = graphed.step(a), eager.step(a)
        for g, w in zip(got[:4], want[:4]):
            assert torch.equal(g, w)
        assert got[4].keys() == want[4].keys()
        assert all(torch.equal(got[4][key], want[4][key]) for key in want[4] if isinstance(want[4][key], torch.Tensor))
        rewards.append(got[1])
    assert len({id(r) for r in rewards[10:]}) == 2           # two graphs (episodes may start, or not), recorded by now
    assert got[4] is not graphed.step(actions[0])[4]          # new dicts around the graph's tensors


@pytest.mark.parametrize("mode", ["same_step", "next_step"])
def test_a_device_drawn_step_is_one_static_graph_without_host_reads(mode):
    """torch.compile(fullgraph=True) captures the whole step (no Python branch on a tensor's value, no
    data-dependent shape), the graphs read nothing back to the host, and they replay the eager env.
    The host's step count picks the graph (steps where episodes may start, and the others: at most
    three graphs with the first step's). The host draw's step does break the graph (at its restart):
    the check can fail."""
    graphs = []

    def recorder(gm, example_inputs):
        graphs.append(gm)
        return gm.forward

    def made(draw):
        env = _make("SoftSphereProcedure-v0", "torch", num_envs=4, target_draw=draw, check_actions=False,
                    autoreset_mode=mode, max_episode_steps=3, dynamics={"kind": "viscoelastic"})
        env.reset(seed=0)
        return env

    torch._dynamo.reset()
    compiled, eager = made("device"), made("device")
    step = torch.compile(compiled.unwrapped.step, backend=recorder, fullgraph=True)
    actions = torch.as_tensor(np.random.default_rng(0).uniform(-1, 1, (8, 4, 4)))
    for a in actions:                                       # 8 steps: two autoresets of every env
        got, want = step(a), eager.step(a)
        assert torch.equal(got[0], want[0]) and torch.equal(got[1], want[1])
        assert torch.equal(got[4]["normalized_score"], want[4]["normalized_score"])
    assert 2 <= len(graphs) <= 3
    for node in (node for graph in graphs for node in graph.graph.nodes):
        name = node.target if isinstance(node.target, str) else getattr(node.target, "__name__", "")
        assert name not in FORBIDDEN, node.format_node()
        value = node.meta.get("example_value")
        if isinstance(value, torch.Tensor):
            assert all(isinstance(d, int) for d in value.shape), node.format_node()
    torch._dynamo.reset()
    host = made("host")
    host_step = torch.compile(host.unwrapped.step, backend=recorder, fullgraph=True)
    with pytest.raises(Exception, match="data-dependent"):
        for a in actions:                                   # breaks at the first step where episodes start
            host_step(a)
    torch._dynamo.reset()


@pytest.mark.parametrize("mode", ["same_step", "next_step"])
@pytest.mark.parametrize("draw", ["host", "device"])
def test_episodes_start_only_on_the_steps_the_host_expects(mode, draw):
    """Without success termination the env skips the episode-start work on steps where no episode can
    end (known from the host's step count): it plays exactly as the env that checks every step."""
    def made():
        env = _make("SoftSphereProcedure-v0", "torch", num_envs=3, target_draw=draw, autoreset_mode=mode,
                    max_episode_steps=5)
        env.reset(seed=3)
        return env

    gated, checked = made(), made()
    checked.unwrapped._episodes_may_start = lambda: True
    gate, opened = gated.unwrapped._episodes_may_start, []
    gated.unwrapped._episodes_may_start = lambda: opened.append(gate()) or opened[-1]
    for a in torch.as_tensor(np.random.default_rng(4).uniform(-1, 1, (23, 3, 4))):
        got, want = gated.step(a), checked.step(a)
        for x, y in zip(got[:4], want[:4]):
            assert torch.equal(x, y)
        assert torch.equal(got[4]["normalized_score"], want[4]["normalized_score"])
    # open on steps 5, 10, 15, 20 (same-step) or 6, 12, 18 (next-step: the step after each end)
    expected = [5, 10, 15, 20] if mode == "same_step" else [6, 12, 18]
    assert [i + 1 for i, was_open in enumerate(opened) if was_open] == expected


@pytest.mark.parametrize("mode", ["same_step", "next_step"])
def test_device_draw_restarts_the_envs_that_succeed(mode):
    """With success termination an episode can end on any step: pressing exactly each env's target
    force succeeds at once, and only those envs start their next episode (the others hold theirs)."""
    env = _make("SoftSphere-v0", "torch", num_envs=4, target_draw="device", autoreset_mode=mode,
                task={"terminate_on_success": True})
    env.reset(seed=0)
    source, device = env.unwrapped._episodes, env.unwrapped.world.force_box
    first = source.features.clone()
    exact = (first.numpy() - device.mid) / device.half
    actions = torch.as_tensor(np.where([[1], [0], [1], [0]], exact, -1.0))       # envs 0 and 2 press their target
    _, _, terminated, truncated, _ = env.step(actions)
    assert terminated.tolist() == [True, False, True, False] and not truncated.any()
    if mode == "next_step":
        assert torch.equal(source.features, first)
        env.step(actions)                                                     # the step that resets them
    assert source.episode.tolist() == [1, 0, 1, 0]
    moved = ~torch.isclose(source.features, first).all(dim=1)
    assert moved.tolist() == [True, False, True, False]
