"""Where an FE scene's data come from: the file shipped with softenv for its request, else the cache,
else solved now with FElupe (the ``fem`` extra) and cached (numpy only until it must solve)."""

from __future__ import annotations

import sys
from pathlib import Path

from .. import _cache
from .._artifact import load_artifact
from ..parallel import usable_cores
from .scene_data import SCENE_DATA_FORMAT, SCENE_DATA_VERSION, FERequest, FESceneData

SHIPPED_DIR = Path(__file__).with_name("shipped")


def shipped_file(request: FERequest) -> Path | None:
    """The file shipped with softenv for ``request``, if there is one (found by its header)."""
    for path in sorted(SHIPPED_DIR.glob("*.npz")):
        _, meta = load_artifact(path, SCENE_DATA_FORMAT, SCENE_DATA_VERSION, header_only=True)
        if FERequest.from_dict(meta["request"]) == request:
            return path
    return None


def scene_data(request: FERequest) -> FESceneData:
    """An FE scene's data: the shipped file made for ``request``, else the cached one, else generated
    now (the ``fem`` extra; minutes, progress on stderr; every ramp is cached, so a stopped generation
    resumes) and cached."""
    path = shipped_file(request)
    if path is not None:
        return FESceneData.load(path, request)

    def generate() -> FESceneData:
        try:
            from .data import fe_scene_data       # FElupe: only now, for data no file holds
        except ImportError as exc:
            raise ImportError(f"tissue.model='fem': softenv ships FE data for the default scene only, and this "
                              f"scene's ({request.n_contacts} contacts x {request.n_loads} loads on mesh "
                              f"{request.mesh['kind']}/{request.mesh['resolution']}, E={request.fe.E:g} Pa, "
                              f"nu={request.fe.nu:g}) must be generated, which needs the fem extra: "
                              f"pip install 'softenv[fem]' ({exc})") from exc
        print(f"softenv: generating the FE data of this scene on {usable_cores()} cores (about 3 min on 2 cores "
              "for the default size); cached afterwards", file=sys.stderr)
        return fe_scene_data(request, jobs=usable_cores(), echo=lambda line: print(line, file=sys.stderr))

    return _cache.cached("fem-scene", {**request.to_dict(), "format": SCENE_DATA_VERSION}, generate,
                         lambda p: FESceneData.load(p, request), lambda data, p: data.save(p))
