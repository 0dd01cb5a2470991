"""The vector entry point of every SoftSphere id: ``gym.make_vec(id, num_envs, vectorization_mode=
"vector_entry_point", backend=...)`` picks the numpy env or the torch twin."""

from __future__ import annotations

from typing import Any

from gymnasium.vector import VectorEnv

from .vector import SoftSphereVectorEnv

BACKENDS = ("numpy", "torch")


def make_vector_env(num_envs: int = 1, backend: str = "numpy", **kwargs: Any) -> VectorEnv:
    """``num_envs`` envs stepped together: ``backend="numpy"`` (:class:`~softenv.envs.vector.SoftSphereVectorEnv`,
    any device) or ``"torch"`` (:class:`~softenv.envs.torch_twin.SoftSphereTorchVectorEnv`, the ideal
    device, on CPU or GPU tensors; its ``torch_device``, ``dtype`` and further keywords pass through)."""
    if backend == "numpy":
        return SoftSphereVectorEnv(num_envs, **kwargs)
    if backend != "torch":
        raise ValueError(f"backend={backend!r} must be 'numpy' or 'torch'")
    from .torch_twin import SoftSphereTorchVectorEnv      # torch: only for the torch backend

    return SoftSphereTorchVectorEnv(num_envs, **kwargs)
