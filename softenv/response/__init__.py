"""Response models: force vector -> shape parameters ``b``, all with one small interface.

``fit(forces, b)``, ``predict(forces)`` (numpy, one vector or many), ``save(path)`` and
``ResponseModel.load(path, shape_model=...)``. See :mod:`softenv.response.base`.
"""

from .anfis import AnfisResponse
from .base import MinMaxScaler, ResponseModel
from .exact import ExactResponse, TabulatedResponse
from .mlp import MLPResponse
from .polynomial import PolynomialResponse

MODELS: dict[str, type[ResponseModel]] = {
    cls.kind: cls for cls in (PolynomialResponse, AnfisResponse, MLPResponse, ExactResponse, TabulatedResponse)
}

load_response = ResponseModel.load

__all__ = ["AnfisResponse", "ExactResponse", "MLPResponse", "MODELS", "MinMaxScaler", "PolynomialResponse",
           "ResponseModel", "TabulatedResponse", "load_response"]
