"""The scene config's typed sections (softenv.sections, which mypy checks every reader against) hold to
the schema that makes and checks the config (softenv.envs.config.SCHEMA), key for key."""

import types
import typing

import numpy as np
import pytest

import softenv
from softenv import sections
from softenv.envs import HAPTIC_SCENES
from softenv.envs.config import SCHEMA, scene_config

SECTION_TYPES = typing.get_type_hints(sections.SceneConfig)


def test_every_section_and_key_of_the_schema_is_typed_and_no_other():
    assert set(SECTION_TYPES) == set(SCHEMA)
    for name, typed in SECTION_TYPES.items():
        assert set(typing.get_type_hints(typed)) == set(SCHEMA[name]), name


def test_a_made_config_holds_the_types_its_sections_declare():
    config = softenv.make_config(device={"kind": "laryngoscope"}, tissue={"E": 5e4})
    for name, typed in SECTION_TYPES.items():
        for key, hint in typing.get_type_hints(typed).items():
            value = config[name][key]
            union = typing.get_origin(hint) in (typing.Union, types.UnionType)
            members = typing.get_args(hint) if union else (hint,)
            origins = tuple(typing.get_origin(t) or t for t in members)
            assert isinstance(value, origins) or (float in origins and type(value) is int), (name, key, value, hint)


def test_an_env_from_a_made_config_steps_as_the_env_from_its_sections():
    """``SoftSphereEnv.from_config`` (the trainee wing's replays) takes the config as made: the same rollout, bit
    for bit, as the env built from the sections; a config with a bad value or sections alone is refused."""
    scene = {"tissue": {"law": "stiffening"}, "task": {"horizon": 20}}
    made = scene_config(HAPTIC_SCENES["SoftSphereHaptic-v0"], scene)
    a, b = softenv.SoftSphereEnv.from_config(made), softenv.SoftSphereEnv(base_scene=HAPTIC_SCENES["SoftSphereHaptic-v0"], **scene)
    actions = np.random.default_rng(3).uniform(-1, 1, (20, 4)).astype(np.float32)
    assert np.array_equal(a.reset(seed=5)[0], b.reset(seed=5)[0])
    for action in actions:
        sa, sb = a.step(action), b.step(action)
        assert np.array_equal(sa[0], sb[0]) and sa[1:4] == sb[1:4]
    with pytest.raises(ValueError, match=r"got \['tissue'\]; make one from sections with make_config"):
        softenv.SoftSphereEnv.from_config({"tissue": {"E": 5e4}})
    bad = {**made, "tissue": {**made["tissue"], "E": -1.0}}
    with pytest.raises(ValueError, match="tissue.E"):
        softenv.SoftSphereEnv.from_config(bad)
