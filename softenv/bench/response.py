"""Benchmarks of the response models: single predict, the haptic update (predict + decode), batches."""

from __future__ import annotations

import numpy as np

from ..datasets import paper_dataset, split_rows
from ..response import AnfisResponse, MLPResponse, PolynomialResponse, ResponseModel
from ..shape_model import ShapeModel
from .timing import Row, Timing, measure, measure_each, spread_us


def paper_models(quick: bool) -> tuple[ShapeModel, np.ndarray, list[tuple[str, ResponseModel, float]]]:
    """The paper's data (961 points, 10 deformations), its shape model and the three regressors, fitted."""
    data = paper_dataset(961, n_deformations=10)
    shape_model = ShapeModel("scree").fit(data.shapes, data.mesh)
    b = shape_model.encode(data.shapes)
    split = split_rows(data.n_samples, seed=0)
    models = [("polynomial, order 3", PolynomialResponse(3, ridge=1e-8), 15e-6),
              ("ANFIS, 16 rules x 10 outputs", AnfisResponse(), 30e-6),
              ("MLP 4-7-9-10", MLPResponse(restarts=1 if quick else 5), 15e-6)]
    for _, model, _ in models:
        model.fit(data.forces[split.train], b[split.train], validation=(data.forces[split.validation], b[split.validation]),
                  shape_model=shape_model)
    return shape_model, data.forces, models


def bench_response(quick: bool, reference: Timing) -> list[Row]:
    shape_model, forces, models = paper_models(quick)
    one = forces[17].copy()
    surface = np.empty(shape_model.n_features_, np.float32)
    rows = []
    for name, model, target in models:
        t = measure(lambda: model.predict(one), number=2000 if quick else 10000)
        rows.append(Row("response", f"{name}: single predict (numpy)", t.median * 1e6, "us", spread_us(t),
                        f"<= {target * 1e6:.0f} us", t.median <= target))

        def haptic_update() -> None:
            shape_model.decode(model.predict(one).astype(np.float32), out=surface)

        h = measure_each(haptic_update, calls=5000 if quick else 50000)
        rows.append(Row("response", f"{name}: haptic update (predict + decode 961 pts)", h.p99 * 1e6, "us (p99)",
                        f"median {h.median * 1e6:.1f} us", "p99 <= 50 us (paper: < 10 ms)", h.p99 <= 50e-6))
    mlp = models[2][1]
    batch = np.repeat(forces, 1000, axis=0)[: 100_000]
    t = measure(lambda: mlp.predict(batch), number=1, repeats=5 if quick else 15)
    rate = batch.shape[0] / t.median
    rows.append(Row("response", "MLP 4-7-9-10: batched predict, 100,000 force vectors", rate, "vectors/s",
                    f"IQR {batch.shape[0] / t.p75:,.0f}-{batch.shape[0] / t.p25:,.0f}", ">= 1,000,000/s", rate >= 1e6))
    return rows
