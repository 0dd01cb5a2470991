"""The scene config's typed sections (softenv.sections, which mypy checks every reader against) hold to
the schema that makes and checks the config (softenv.envs.config.SCHEMA), key for key."""

import types
import typing

import softenv
from softenv import sections
from softenv.envs.config import SCHEMA

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
