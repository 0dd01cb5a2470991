"""What people who extend softenv import: the env classes, the device contract and the response models
from the package's top level, without a deep import, and without loading what a scene does not use."""

import ast
from pathlib import Path

import softenv
from softenv.devices import base
from softenv.envs.single import SoftSphereEnv
from softenv.envs.vector import SoftSphereVectorEnv

ROOT = Path(__file__).resolve().parent.parent


def test_the_top_level_exports_the_env_classes_the_device_contract_and_make_response():
    assert softenv.SoftSphereEnv is SoftSphereEnv and softenv.SoftSphereVectorEnv is SoftSphereVectorEnv
    for name in ("Device", "DeviceBatch", "DeviceTensors", "DeviceKind", "DeviceScene", "Config"):
        assert getattr(softenv, name) is getattr(base, name), name
    assert softenv.make_response("poly2").__class__.__name__ == "PolynomialResponse"
    assert set(softenv.__all__) <= set(dir(softenv))


def test_the_torch_twin_loads_torch_only_when_named(heavy_modules_after):
    assert heavy_modules_after("import softenv\n") == []
    assert heavy_modules_after("import softenv\nsoftenv.SoftSphereTorchVectorEnv\n") == ["torch"]


def test_the_device_example_imports_public_names_only():
    """examples/probe_device.py, the adding-a-device page's device, imports softenv's top level only."""
    tree = ast.parse((ROOT / "examples" / "probe_device.py").read_text())
    deep = [node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)
            and node.module and node.module.startswith("softenv.")]
    assert not deep, deep
