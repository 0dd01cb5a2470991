"""baselines/fingerprint.py: the digest a kept run is reused by changes exactly when the dynamics do,
for every kind of env a learner trains on (numpy twin, torch twin, stable-baselines3's adapter)."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import pytest

from softenv.baselines.evaluate import scene_kwargs
from softenv.baselines.fingerprint import PROBE_ENVS, probe_steps, rollout_digest

SCENE = "SoftSphere-v0"


def _twin(E: float, **options: Any) -> Any:
    """A factory of ``SCENE``'s vector env on a split, with the tissue's Young's modulus ``E``."""
    def make(split: str) -> Any:
        env_id, kwargs = scene_kwargs(SCENE, split=split)
        kwargs["tissue"] = {**kwargs.get("tissue", {}), "E": E}
        return gym.make_vec(env_id, num_envs=PROBE_ENVS, vectorization_mode="vector_entry_point", **kwargs, **options)
    return make


@pytest.mark.parametrize("options", [{}, {"backend": "torch"}], ids=["numpy", "torch"])
def test_the_digest_repeats_and_moves_with_the_tissue(options: dict[str, Any]) -> None:
    if options:
        pytest.importorskip("torch")
    steps = probe_steps(scene_kwargs(SCENE)[1])
    E = scene_kwargs(SCENE)[1].get("tissue", {}).get("E", 6.0)
    same = rollout_digest(_twin(E, **options), steps)
    assert same == rollout_digest(_twin(E, **options), steps)
    assert rollout_digest(_twin(E * (1 + 1e-6), **options), steps) != same      # stiffer by a part in a million
    assert rollout_digest(_twin(E, **options), steps - 1) != same              # the probe's length is part of it


def test_the_probe_runs_one_episode_and_into_the_next() -> None:
    assert probe_steps(scene_kwargs(SCENE)[1]) == 110                          # SoftSphere-v0: 100-step episodes
    assert probe_steps(scene_kwargs("SoftSphereHapticProcedure-v0")[1]) == 510
