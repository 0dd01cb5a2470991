"""Response models: force vector -> shape parameters ``b``, all with one small interface.

``fit(forces, b)``, ``predict(forces)`` (numpy, one vector or many), ``save(path)`` and
``ResponseModel.load(path, shape_model=...)``. See :mod:`softenv.response.base`.
"""

from typing import Any

from .anfis import AnfisResponse
from .base import MODELS, MinMaxScaler, ResponseModel
from .exact import ExactResponse, TabulatedResponse, tabulate
from .mlp import MLPResponse
from .polynomial import PolynomialResponse
from .rbf import RBFResponse

load_response = ResponseModel.load

# Named configurations. "paper" ones follow the paper and MATLAB's defaults; the others are tuned.
REGRESSORS: dict[str, str] = {
    "poly1": "polynomial least squares, order 1 (paper eq. 2.5)",
    "poly2": "polynomial least squares, order 2 (eq. 2.6), ridge 1e-8",
    "poly3": "polynomial least squares, order 3 (eq. 2.7), ridge 1e-8",
    "anfis": "ANFIS, 2 gbell MFs per input (16 rules), 10 epochs: MATLAB defaults",
    "anfis100": "ANFIS as 'anfis' with 100 epochs",
    "mlp": "MLP 4-7-9-k, tansig, Levenberg-Marquardt (trainlm), 5 restarts: the paper's net",
    "mlp20": "MLP 4-20-20-k, 3 restarts, otherwise as 'mlp'",
}


def make_response(name: str, seed: int = 0, clip: bool = False, **mlp_options: Any) -> ResponseModel:
    """A regressor by name (see ``REGRESSORS``). ``mlp_options`` (e.g. ``trainer="lbfgs"``,
    ``restarts=3``) override the MLP set-ups' arguments and are refused for the other models."""
    if mlp_options and not name.startswith("mlp"):
        raise ValueError(f"options {sorted(mlp_options)} apply to MLP regressors only, not {name!r}")
    factories = {
        "poly1": lambda: PolynomialResponse(1, clip=clip),
        "poly2": lambda: PolynomialResponse(2, ridge=1e-8, clip=clip),
        "poly3": lambda: PolynomialResponse(3, ridge=1e-8, clip=clip),
        "anfis": lambda: AnfisResponse(clip=clip),
        "anfis100": lambda: AnfisResponse(epochs=100, clip=clip),
        "mlp": lambda: MLPResponse(**{"seed": seed, "clip": clip, **mlp_options}),
        "mlp20": lambda: MLPResponse(**{"hidden": (20, 20), "restarts": 3, "seed": seed, "clip": clip, **mlp_options}),
    }
    if name not in factories:
        raise ValueError(f"unknown regressor {name!r}; choose one of {list(factories)}")
    return factories[name]()


__all__ = ["AnfisResponse", "ExactResponse", "MLPResponse", "MODELS", "MinMaxScaler", "PolynomialResponse",
           "RBFResponse", "REGRESSORS", "ResponseModel", "TabulatedResponse", "load_response", "make_response", "tabulate"]
