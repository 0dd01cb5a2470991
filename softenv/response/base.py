"""The one interface of every response model: force vectors in, shape parameters ``b`` out.

A response model is a scikit-learn-style estimator: hyper-parameters in ``__init__``, learned state
ending in ``_``, ``fit(forces, b)`` and ``predict(forces)``. Inputs and outputs are scaled to
``[-1, 1]`` on the training data (MATLAB's ``mapminmax``, as the paper's tools did). Prediction is
numpy only. A model fitted for a shape model records that model's fingerprint; loading it for
another shape model is an error naming both.
"""

from __future__ import annotations

import os
from typing import Any, ClassVar

import numpy as np

from .._artifact import load_artifact, require_arrays, save_artifact
from .._validation import check_array
from ..shape_model import ShapeModel

RESPONSE_FORMAT = "softenv.ResponseModel"
RESPONSE_VERSION = 1
# every response model class by its kind (a saved model names its kind): each registers itself when defined
MODELS: dict[str, type["ResponseModel"]] = {}


class MinMaxScaler:
    """Affine map of each column onto ``[-1, 1]`` (MATLAB ``mapminmax``); constant columns map to 0."""

    def __init__(self, scale: np.ndarray, offset: np.ndarray) -> None:
        self.scale = np.asarray(scale, dtype=np.float64)
        self.offset = np.asarray(offset, dtype=np.float64)

    @classmethod
    def fit(cls, X: np.ndarray) -> "MinMaxScaler":
        lo, hi = X.min(axis=0), X.max(axis=0)
        span = hi - lo
        scale = np.where(span > 0, 2.0 / np.where(span > 0, span, 1.0), 1.0)
        offset = np.where(span > 0, -1.0 - lo * scale, -lo)
        return cls(scale, offset)

    def transform(self, X: np.ndarray) -> np.ndarray:
        return X * self.scale + self.offset

    def inverse(self, Y: np.ndarray) -> np.ndarray:
        return (Y - self.offset) / self.scale


class ResponseModel:
    """Base class: maps force vectors ``(N, d)`` to shape parameters ``(N, k)``.

    Subclasses implement ``_fit_scaled(x, y, validation)`` and ``_predict_scaled(x)`` on inputs and
    outputs already scaled to ``[-1, 1]``, and list their learned arrays in ``_state()``.

    Args:
        clip: clip predictions to the plausible range of ``b`` (the shape model's data range when
            fitted with one, else the training targets' range).
    """

    kind: ClassVar[str] = "base"

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if "kind" in cls.__dict__:                   # a model of its own kind (not a tweak of one) can be loaded
            MODELS[cls.kind] = cls

    def __init__(self, *, clip: bool = False) -> None:
        self.clip = bool(clip)

    # -- public interface -------------------------------------------------------------------------

    def fit(self, forces: np.ndarray, b: np.ndarray, *, validation: tuple[np.ndarray, np.ndarray] | None = None,
            shape_model: ShapeModel | None = None) -> "ResponseModel":
        """Learn ``forces -> b``. ``validation`` (forces, b) is used for early stopping / model selection
        where the model has such a step; ``shape_model`` binds the model to that shape space."""
        X = check_array(forces, "forces", ndim=2)
        Y = check_array(b, "b", ndim=2)
        if X.shape[0] != Y.shape[0]:
            raise ValueError(f"forces has {X.shape[0]} rows but b has {Y.shape[0]}; they must match")
        if shape_model is not None and Y.shape[1] != shape_model.n_components_:
            raise ValueError(f"b has {Y.shape[1]} columns but the shape model has k={shape_model.n_components_}")
        self.n_features_, self.n_outputs_ = X.shape[1], Y.shape[1]
        self.input_scaler_ = MinMaxScaler.fit(X)
        self.output_scaler_ = MinMaxScaler.fit(Y)
        if shape_model is not None:
            self.shape_model_fingerprint_ = shape_model.fingerprint()
            self.b_low_, self.b_high_ = shape_model.b_min_.copy(), shape_model.b_max_.copy()
        else:
            self.shape_model_fingerprint_ = ""
            self.b_low_, self.b_high_ = Y.min(axis=0), Y.max(axis=0)
        scaled_val = None
        if validation is not None:
            Xv = check_array(validation[0], "validation forces", ndim=2, shape=(self.n_features_,))
            Yv = check_array(validation[1], "validation b", ndim=2, shape=(self.n_outputs_,))
            scaled_val = (self.input_scaler_.transform(Xv), self.output_scaler_.transform(Yv))
        self._fit_scaled(self.input_scaler_.transform(X), self.output_scaler_.transform(Y), scaled_val)
        return self

    def predict(self, forces: np.ndarray, *, return_clipped: bool = False) -> Any:
        """Shape parameters for ``(d,)`` or ``(N, d)`` force vectors.

        With ``clip=True`` outputs are clipped to ``[b_low_, b_high_]``; ``return_clipped=True`` also
        returns a boolean array telling which outputs were clipped (or would be, with ``clip=False``).
        """
        self._check_fitted()
        X = check_array(forces, "forces", ndim=(1, 2), shape=(self.n_features_,))
        single = X.ndim == 1
        x = self.input_scaler_.transform(X.reshape(1, -1) if single else X)
        y = self.output_scaler_.inverse(self._predict_scaled(x))
        outside = (y < self.b_low_) | (y > self.b_high_) if (self.clip or return_clipped) else None
        if self.clip:
            y = np.clip(y, self.b_low_, self.b_high_)
        if single:
            y = y[0]
            outside = None if outside is None else outside[0]
        return (y, outside) if return_clipped else y

    def predict_rowwise(self, x: np.ndarray) -> np.ndarray:
        """Predictions for ``(N, d)`` force vectors whose every row is bit-identical to predicting that
        row alone, whatever ``N`` (no BLAS products, whose rounding depends on the batch shape).

        For environments, where one env and a batch of them must agree exactly. Inputs are not
        validated; clipping follows ``clip``.
        """
        y = self.output_scaler_.inverse(self._predict_scaled_rowwise(self.input_scaler_.transform(x)))
        return np.clip(y, self.b_low_, self.b_high_) if self.clip else y

    def _predict_scaled_rowwise(self, x: np.ndarray) -> np.ndarray:
        raise NotImplementedError(f"{type(self).__name__} has no row-wise prediction")

    # -- persistence ------------------------------------------------------------------------------

    def save(self, path: str | os.PathLike) -> None:
        """Write a versioned ``.npz`` with plain arrays only (atomic)."""
        self._check_fitted()
        arrays = {"input_scale": self.input_scaler_.scale, "input_offset": self.input_scaler_.offset,
                  "output_scale": self.output_scaler_.scale, "output_offset": self.output_scaler_.offset,
                  "b_low": self.b_low_, "b_high": self.b_high_}
        arrays.update({f"state_{k}": v for k, v in self._state().items()})
        save_artifact(path, RESPONSE_FORMAT, RESPONSE_VERSION, arrays,
                      {"model": self.kind, "params": self._params(), "n_features": self.n_features_,
                       "n_outputs": self.n_outputs_, "shape_model": self.shape_model_fingerprint_,
                       "extra": self._extra_meta()})

    @classmethod
    def load(cls, path: str | os.PathLike, shape_model: ShapeModel | None = None) -> "ResponseModel":
        """Read a model written by :meth:`save` (any kind when called on the base class)."""
        arrays, meta = load_artifact(path, RESPONSE_FORMAT, RESPONSE_VERSION)
        require_arrays(arrays, ["input_scale", "input_offset", "output_scale", "output_offset", "b_low", "b_high"], path)
        kind = meta.get("model")
        if kind not in MODELS:
            raise ValueError(f"{str(path)!r} holds an unknown response model {kind!r}; known: {sorted(MODELS)}")
        model_cls = MODELS[kind]
        if cls is not ResponseModel and not issubclass(model_cls, cls):
            raise ValueError(f"{str(path)!r} holds a {kind!r} model, not a {cls.kind!r} model")
        recorded = meta.get("shape_model", "")
        if shape_model is not None and recorded and recorded != shape_model.fingerprint():
            raise ValueError(f"{str(path)!r} was fitted for shape model {recorded!r}, not for the given shape model "
                             f"{shape_model.fingerprint()!r} (another mesh or k)")
        try:
            model = model_cls._from_saved(meta["params"], arrays, meta, shape_model, path)
        except (KeyError, TypeError, AttributeError) as exc:
            raise ValueError(f"{str(path)!r} has an invalid {kind!r} header (missing or bad {exc})") from exc
        model.b_low_, model.b_high_ = arrays["b_low"], arrays["b_high"]
        model.shape_model_fingerprint_ = recorded
        expected = {"input_scale": model.n_features_, "input_offset": model.n_features_, "output_scale": model.n_outputs_,
                    "output_offset": model.n_outputs_, "b_low": model.n_outputs_, "b_high": model.n_outputs_}
        for name, size in expected.items():
            if arrays[name].shape != (size,):
                raise ValueError(f"{str(path)!r}: array {name!r} has shape {arrays[name].shape}; expected ({size},) for "
                                 f"n_features={model.n_features_}, n_outputs={model.n_outputs_}")
        return model

    @classmethod
    def _from_saved(cls, params: dict[str, Any], arrays: dict[str, np.ndarray], meta: dict[str, Any],
                    shape_model: ShapeModel | None, path: Any) -> "ResponseModel":
        """Rebuild a model from its saved parameters, scalers and learned arrays."""
        model = cls(**params)
        model.n_features_, model.n_outputs_ = int(meta["n_features"]), int(meta["n_outputs"])
        model.input_scaler_ = MinMaxScaler(arrays["input_scale"], arrays["input_offset"])
        model.output_scaler_ = MinMaxScaler(arrays["output_scale"], arrays["output_offset"])
        model._set_state({k[len("state_"):]: v for k, v in arrays.items() if k.startswith("state_")},
                         meta.get("extra", {}), path)
        return model

    # -- subclass hooks ---------------------------------------------------------------------------

    def _fit_scaled(self, x: np.ndarray, y: np.ndarray, validation: tuple[np.ndarray, np.ndarray] | None) -> None:
        raise NotImplementedError

    def _predict_scaled(self, x: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def _params(self) -> dict[str, Any]:
        """Constructor arguments, JSON-serialisable."""
        return {"clip": self.clip}

    def _state(self) -> dict[str, np.ndarray]:
        return {}

    def _extra_meta(self) -> dict[str, Any]:
        return {}

    def _set_state(self, state: dict[str, np.ndarray], extra: dict[str, Any], path: Any) -> None:
        pass

    def _check_fitted(self) -> None:
        if not hasattr(self, "input_scaler_"):
            raise RuntimeError(f"this {type(self).__name__} is not fitted yet: call fit(forces, b) or load(path)")

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self._params().items())
        return f"{type(self).__name__}({args})"
