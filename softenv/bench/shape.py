"""Benchmarks of the offline and reconstruction core: tissue model and PCA shape model."""

from __future__ import annotations

import json
import subprocess
import sys
import time

import numpy as np

from ..datasets import paper_dataset
from ..forces import DorsumLayout, Workspace, sample_workspace
from ..geometry import latlong_mesh
from ..shape_model import ShapeModel, decode_block_rows
from ..tissue import AnalyticTissue, TissueParams
from .timing import Row, Timing, measure, spread_us


def bench_decode(quick: bool, reference: Timing) -> list[Row]:
    """Decode 961 points with k = 10 in float32 against one read of the components; batched decode
    against the memory bandwidth of writing the output."""
    data = paper_dataset(961, n_deformations=10)
    model = ShapeModel(10).fit(data.shapes, data.mesh)
    b = model.encode(data.shapes[7]).astype(np.float32)
    out = np.empty(model.n_features_, np.float32)
    phi = model.augmented(np.float32)[1:].ravel()
    ones = np.ones_like(phi)
    number = 5000 if quick else 20000
    decode = measure(lambda: model.decode(b, out=out), number=number)
    read = measure(lambda: np.dot(phi, ones), number=number)
    ratio = decode.median / read.median
    rows = [
        Row("shape model", "decode 961 pts, k=10, float32, one shape", decode.median * 1e6, "us", spread_us(decode),
            "<= 5 us (paper: < 10 ms)", decode.median <= 5e-6),
        Row("shape model", "one read of Phi (10 x 2883 float32)", read.median * 1e6, "us", spread_us(read)),
        Row("shape model", "decode / one read of Phi", ratio, "x", "", "<= 2.5x", ratio <= 2.5),
    ]
    n = 20_000 if quick else 100_000
    batch = model.encode(data.shapes[np.arange(n) % data.n_samples]).astype(np.float32)
    big = np.empty((n, model.n_features_), np.float32)
    big.fill(0.0)  # touch the pages before timing
    dec = measure(lambda: model.decode(batch, out=big), number=1, repeats=5)
    fill = measure(lambda: big.fill(1.0), number=1, repeats=5)
    gbps = big.nbytes / fill.median / 1e9
    # the same products into one cache-resident block: the arithmetic alone, with no output traffic
    aug = model.augmented(np.float32)
    lifted = np.hstack([np.ones((n, 1), np.float32), batch])
    block = np.empty((decode_block_rows(model.n_features_, len(aug), 4), model.n_features_), np.float32)
    starts = range(0, n - len(block) + 1, len(block))
    compute = measure(lambda: [np.dot(lifted[s:s + len(block)], aug, out=block) for s in starts], number=1, repeats=5)
    per_shape = compute.median / (len(starts) * len(block))
    rows += [
        Row("shape model", f"batched decode, {n:,} shapes x 961 pts (float32)", dec.median * 1e3, "ms",
            f"IQR {dec.p25 * 1e3:.1f}-{dec.p75 * 1e3:.1f} ms"),
        Row("shape model", f"write floor: fill the {big.nbytes / 1e9:.2f} GB output", fill.median * 1e3, "ms",
            f"{gbps:.1f} GB/s"),
        Row("shape model", "batched decode / write floor", dec.median / fill.median, "x", "", "<= 2x",
            dec.median / fill.median <= 2.0),
        Row("shape model", "its arithmetic alone (same products into one L2-resident block) / write floor",
            per_shape * n / fill.median, "x", f"{2 * aug.size / per_shape / 1e9:.0f} GFLOP/s"),
    ]
    return rows


def bench_fit(quick: bool, reference: Timing) -> list[Row]:
    data = paper_dataset(961, n_deformations=10)
    fit = measure(lambda: ShapeModel("scree").fit(data.shapes, data.mesh), number=5 if quick else 20, repeats=7)
    rows = [Row("shape model", "fit, paper data 110 x 2883 (Gram + scree)", fit.median * 1e3, "ms",
                f"IQR {fit.p25 * 1e3:.2f}-{fit.p75 * 1e3:.2f} ms", "<= 20 ms", fit.median <= 0.02)]
    samples = 2000 if quick else 10000
    result = run_large_fit(samples, 100, 20)
    target = "<= 60 s, <= 4 GB" if not quick else "full run: 10,000 samples"
    ok = (result["fit_s"] <= 60 and result["peak_rss_gb"] <= 4) if not quick else None
    rows.append(Row("shape model", f"randomized fit {samples:,} x 30,000, k=20", result["fit_s"], "s",
                    f"peak RSS {result['peak_rss_gb']:.2f} GB, data {result['data_gb']:.2f} GB, "
                    f"generated in {result['generate_s']:.1f} s", target, ok, {"peak_rss_gb": result["peak_rss_gb"]}))
    return rows


def bench_tissue(quick: bool, reference: Timing) -> list[Row]:
    mesh = latlong_mesh(31)
    tissue = AnalyticTissue(mesh)
    ws = Workspace((0.02, -0.01, 0.0, -10.0), (0.07, 0.01, 40.0, 10.0))
    forces, _ = sample_workspace(ws, 512, 8, seed=0)
    loads = DorsumLayout(mesh.radius).to_loads(forces)
    t = measure(lambda: tissue.surfaces(*loads), number=1, repeats=3 if quick else 7)
    rate = forces.shape[0] / t.median
    return [Row("tissue", "analytic tissue, 961 pts, batched", rate, "force vectors/s",
                f"IQR {forces.shape[0] / t.p75:,.0f}-{forces.shape[0] / t.p25:,.0f}", ">= 10,000/s", rate >= 10_000)]


def run_large_fit(n_samples: int, grid: int, k: int) -> dict[str, float]:
    """Randomized PCA of ``n_samples`` surfaces on a ``grid x grid`` mesh in a fresh process (own peak memory)."""
    cmd = [sys.executable, "-m", "softenv.bench.shape", str(n_samples), str(grid), str(k)]
    out = subprocess.run(cmd, check=True, capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _large_fit_main(n_samples: int, grid: int, k: int) -> None:
    import resource                                         # Unix only

    mesh = latlong_mesh(grid)
    tissue = AnalyticTissue(mesh, TissueParams())
    ws = Workspace((0.02, -0.01, 0.0, -10.0), (0.07, 0.01, 40.0, 10.0))
    forces, _ = sample_workspace(ws, n_samples // 10, 10, seed=0)
    contacts, vectors = DorsumLayout(mesh.radius).to_loads(forces)
    t0 = time.perf_counter()
    X = np.empty((n_samples, 3 * mesh.n_vertices), np.float32)
    for start in range(0, n_samples, 256):
        X[start:start + 256] = tissue.surfaces(contacts[start:start + 256], vectors[start:start + 256])
    t1 = time.perf_counter()
    model = ShapeModel(k, solver="randomized").fit(X)
    t2 = time.perf_counter()
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024 ** 2  # KiB -> GiB
    print(json.dumps({"generate_s": t1 - t0, "fit_s": t2 - t1, "peak_rss_gb": peak, "data_gb": X.nbytes / 1024 ** 3,
                      "k": model.n_components_}))


if __name__ == "__main__":
    _large_fit_main(int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]))
