"""The laryngoscope as a part a vector env composes (:class:`~softenv.devices.base.DeviceBatch`), on
the batch engine ``device.batch_engine`` names; what it shares with the single device's part is
:mod:`.part` (a module of its own so that a single env does not load Warp)."""

from __future__ import annotations

from typing import Any

import numpy as np

from . import clinical
from ..._ops import ArrayOps
from ..base import Config, DeviceScene
from . import LARYNGOSCOPE_OBS
from .batch import ArrayLaryngoscopes, LaryngoscopeBatch
from .part import INFO_KEYS, PickledByState, batch_report, glottic_view, in_workspace, laryngoscope_parts
from .state import DeviceState



def batch_engine(name: str) -> type[ArrayLaryngoscopes]:
    """The numpy twin's engine ``device.batch_engine`` names: ``auto`` and ``warp`` the Warp kernel
    (:class:`~.warp_arrays.LaryngoscopeWarp`), ``pymunk`` one pymunk space (:class:`~.batch.LaryngoscopeBatch`)."""
    if name == "pymunk":
        return LaryngoscopeBatch
    if name not in ("auto", "warp"):
        raise ValueError(f"device.batch_engine={name!r} has no numpy engine: {name!r} steps only the torch twin's "
                         "CUDA tensors (backend='torch', torch_device='cuda'); the numpy twin takes 'auto', 'warp' "
                         "or 'pymunk'")
    from .warp_arrays import LaryngoscopeWarp      # warp: only for batches on its engine

    return LaryngoscopeWarp


class LaryngoscopePartBatch(PickledByState):
    """``n`` laryngoscopes in a vector env (:class:`~softenv.devices.base.DeviceBatch`) on the engine
    ``device.batch_engine`` names (:func:`batch_engine`): ``warp`` (:class:`~.warp_arrays.LaryngoscopeWarp`,
    the default) equals single devices bit for bit; ``pymunk`` (:class:`~.batch.LaryngoscopeBatch`, one space) does for device 0, the others agree to
    rounding (each sits at its own place in the space)."""

    obs_names = LARYNGOSCOPE_OBS
    info_keys = INFO_KEYS
    episode_info_keys = ("clinical",)
    physics_name = "laryngoscopes"

    def __init__(self, scene: DeviceScene, config: Config, n: int) -> None:
        self._scene, self._config = scene, config
        self.laryngoscopes = self._rebuilt_for(n)
        self._start_state = self.laryngoscopes.start_state(n)
        self._workspace = scene.workspace
        self._rest = scene.rest_features
        self._weights = config["reward"].copy()
        self.clinical = clinical.ClinicalRecorder(n, config["dynamics"]["dt"], config["task"]["horizon"])

    def _clinical_values(self) -> np.ndarray:
        return np.stack(np.broadcast_arrays(*self.laryngoscopes.clinical_values()), axis=1)

    def reset(self, mask: np.ndarray) -> np.ndarray:
        self.laryngoscopes.load_state(self._start_state, rows=mask)
        self.clinical.start(mask, self._clinical_values()[mask])
        return np.zeros(4)

    def act(self, actions: np.ndarray, stepped: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        dev, box = self.laryngoscopes, self._workspace
        dev.control_step(actions, moving=stepped)
        features, touching = dev.features()
        return in_workspace(features, touching, box.low, box.high, self._rest, ArrayOps), dev.normal_force, dev.sideways_force

    def observation(self, features: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        obs = self.laryngoscopes.observation()
        return obs if mask is None else obs[mask]

    def report(self, info: dict[str, Any], stepped: np.ndarray) -> np.ndarray:
        term, values = batch_report(self.laryngoscopes, self._weights)
        info.update(values)
        rows = np.flatnonzero(stepped)
        self.clinical.record(rows, self._clinical_values()[rows])
        return term

    def clinical_summary(self, i: int, b: np.ndarray) -> dict[str, float]:
        """Device ``i``'s episode so far (see :meth:`LaryngoscopePart.clinical_summary`)."""
        return self.clinical.summary(i, glottic_view(self._scene, b))

    def episode_info(self, i: int, b: np.ndarray) -> dict[str, Any]:
        return {"clinical": self.clinical_summary(i, b)}

    def drawing(self, i: int) -> dict[str, Any]:
        return self.laryngoscopes.drawing()[i]

    def state(self) -> Any:
        return self.laryngoscopes.state()

    def load_state(self, state: Any) -> None:
        self.laryngoscopes.load_state(state)

    def _rebuilt_for(self, n: int) -> ArrayLaryngoscopes:
        engine = batch_engine(self._config["device"]["batch_engine"])
        return engine(*laryngoscope_parts(self._scene, self._config), n)

    def _rebuilt(self, state: DeviceState) -> ArrayLaryngoscopes:
        return self._rebuilt_for(len(state.blade))
