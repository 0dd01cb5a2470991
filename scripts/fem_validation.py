"""The finite-element tongue verified, and set beside the analytic tissue.

    python scripts/fem_validation.py --out results

Writes results/fem.md (and fem_indentation.png, fem_error_vs_runtime.png):
1. the homogeneous stretch of a cube against the closed form, and Hooke's law at small strain;
2. equilibrium: the base's force against the blade's, for an oblique press;
3. mesh convergence: the indentation at half the design force (20 N; 16 cells a side do not reach
   40 N) on 4, 8 and 16 cells a side (``--finest``), and the observed order;
4. the FE tongue beside the analytic tissue (linear and stiffening laws, same radius, patch and
   small-strain stiffness): indentation against force, and the surface error between them on the
   paper's 441-point grid at the design force, by geodesic distance from the contact;
5. the paper's protocol on the FE tongue (10 deformations x 11 magnitudes up to 8 N, each ramp's
   load steps the samples; ``--jobs`` workers): how many PCA components the scree test and the
   noise floor keep per number of deformations, at 441 and 961 points, beside the analytic data;
6. the paper's regressors on those FE data beside the analytic data: surface error against the
   haptic update's run time, random rows and held-out contacts (scripts/evaluate_regressors.py's
   evaluation, ``--seeds`` seeds), at 441 and 961 points.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

from softenv._artifact import save_figure, write_text
from softenv.datasets import paper_dataset, split_by_contact, split_rows
from softenv.fem.data import fe_paper_dataset
from softenv.fem.tongue import FEParams, FETongue
from softenv.fem.verification import stretch_unit_cube, uniaxial_closed_form
from softenv.geometry import geodesic_distance, paper_mesh
from softenv.shape_model import ShapeModel
from softenv.tissue import CLINICAL_MAX_FORCE_N, AnalyticTissue, TissueParams
from softenv.bench.timing import code_revision

DESIGN = CLINICAL_MAX_FORCE_N
STEPS = 10


def top_indentation(tongue: FETongue, force: float, steps: int = STEPS) -> tuple[np.ndarray, np.ndarray, float]:
    """Indentation (m) of the top pole at each load step of a vertical press ramped to ``force``."""
    started = time.perf_counter()
    solution = tongue.solve([0.0, 0.0, 1.0], [0.0, 0.0, -force], steps=steps)
    top = int(np.argmax(tongue.points[:, 2]))
    return solution.fractions * force, -solution.displacements[:, top, 2], time.perf_counter() - started


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default="results")
    parser.add_argument("--jobs", type=int, default=2, help="worker processes for the FE data of sections 5-6")
    parser.add_argument("--seeds", type=int, default=2, help="data seeds of section 6")
    parser.add_argument("--finest", type=int, default=16, help="finest mesh of the convergence study (cells a side; "
                        "it also runs a quarter and half of it)")
    args = parser.parse_args()
    started = time.perf_counter()
    base = FEParams()
    lines = ["# The finite-element tongue: verification, and the analytic tissue beside it", ""]

    lines += ["## 1. Closed forms", "",
              f"Unit cube, 2 x 2 x 2 cells, symmetry planes, top face moved (E = {base.E / 1e3:.1f} kPa, "
              f"nu = {base.nu}): FE against the closed-form uniaxial stretch of the same strain energy.", "",
              "| stretch | lateral stretch FE | closed form | nominal stress FE (Pa) | closed form | rel. error |",
              "|---|---|---|---|---|---|"]
    for stretch in (0.7, 1.3, 1.6, 2.0):
        lateral, force = stretch_unit_cube(stretch, base, steps=8)
        want_lateral, want_stress = uniaxial_closed_form(stretch, base)
        lines.append(f"| {stretch} | {lateral:.10f} | {want_lateral:.10f} | {force:.6g} | {want_stress:.6g} | "
                     f"{abs(force / want_stress - 1):.1e} |")
    eps = 1e-6
    lateral, force = stretch_unit_cube(1.0 + eps, base, steps=1)
    lines += ["", f"Small strain (1e-6): Young's modulus {force / eps / 1e3:.4f} kPa (set {base.E / 1e3:.4f}), "
              f"Poisson's ratio {-(lateral - 1) / eps:.5f} (set {base.nu}).", ""]

    tongue8 = FETongue(FEParams(cells_per_side=8))
    force_vec = np.array([8.0, -4.0, -30.0])
    press = tongue8.solve([0.3, 0.1, 1.0], force_vec, steps=STEPS)
    residual = np.abs(press.support + press.fractions[:, None] * force_vec).max()
    lines += ["## 2. Equilibrium", "",
              f"Oblique press {force_vec.tolist()} N at (0.3, 0.1, 1) on 8 cells a side: the fixed base pushes back "
              f"with {press.support[-1].round(9).tolist()} N; the largest imbalance over the {STEPS} load steps is "
              f"{residual:.1e} N.", ""]

    lines += ["## 3. Mesh convergence", "",
              f"Indentation of the top pole under {DESIGN / 2:g} N on the patch ({STEPS} load steps; on 16 cells a "
              f"side the design force's last step does not converge).", "",
              "| cells a side | nodes | dofs | indentation (mm) | of the radius | solve (s) |", "|---|---|---|---|---|---|"]
    depths = []
    for n in (args.finest // 4, args.finest // 2, args.finest):
        tongue = tongue8 if n == 8 else FETongue(FEParams(cells_per_side=n))
        forces, depth, seconds = top_indentation(tongue, DESIGN / 2)
        depths.append(depth[-1])
        m = len(tongue.points)
        lines.append(f"| {n} | {m} | {3 * m} | {depth[-1] * 1e3:.4f} | {depth[-1] / base.radius:.3f} | {seconds:.1f} |")
    fe_forces, fe_depth, _ = top_indentation(tongue8, DESIGN)
    first, second = depths[1] - depths[0], depths[2] - depths[1]
    order = math.log2(abs(first / second))                                   # each mesh halves the cell
    how = ("from one side" if first * second > 0 else
           "oscillating: the coarsest mesh is too stiff, the finer ones approach from above")
    lines += ["", f"Differences {1e3 * first:.4f} mm then {1e3 * second:.4f} mm ({how}): observed order "
              f"{order:.2f} from their sizes; the middle mesh is {100 * abs(second / depths[2]):.1f} % from the "
              "finest.", ""]

    grid = paper_mesh(441, base.radius)
    lines += ["## 4. Beside the analytic tissue", "",
              "Same radius, patch and small-strain stiffness: each analytic law uses the FE tongue's E and nu, so "
              "the two agree on the compliance of a patch on a half-space. Top-pole indentation (mm):", "",
              "| force (N) | FE, 8 cells a side | analytic linear | analytic stiffening |", "|---|---|---|---|"]
    analytic = {law: AnalyticTissue(grid, TissueParams(law=law, E=base.E, nu=base.nu)) for law in ("linear", "stiffening")}
    top = np.array([[0.0, 0.0, base.radius]])
    curves = {law: [] for law in analytic}
    for f, d in zip(fe_forces, fe_depth):
        row = [f"| {f:.0f} | {d * 1e3:.2f}"]
        for law, tissue in analytic.items():
            w = float(tissue.amplitudes(top, np.array([[0.0, 0.0, -f]]))["indentation"][0])
            curves[law].append(w)
            row.append(f"{w * 1e3:.2f}")
        lines.append(" | ".join(row) + " |")
    fe_surface = tongue8.displacements_at(press.displacements[-1], grid.vertices)
    contact = np.array([0.3, 0.1, 1.0]) / np.linalg.norm([0.3, 0.1, 1.0]) * base.radius
    distance = geodesic_distance(grid.vertices, contact[None, :], base.radius).ravel()
    lines += ["", "Surface displacement on the paper's 441-point grid for the oblique press of section 2 (the FE "
              "field interpolated with the elements' shape functions), FE against analytic, by geodesic distance "
              "from the contact (mm):", "",
              "| distance from the contact (mm) | points | FE mean abs (mm) | linear: RMS difference | stiffening: RMS difference |",
              "|---|---|---|---|---|"]
    differences = {law: tissue.displacements(contact[None, :], force_vec[None, :])[0] - fe_surface
                   for law, tissue in analytic.items()}
    edges = np.array([0.0, 10.0, 20.0, 40.0, 60.0, 100.0]) * 1e-3
    for lo, hi in zip(edges[:-1], edges[1:]):
        rows = (distance >= lo) & (distance < hi)
        if rows.any():
            cells = [f"{np.sqrt((differences[law][rows] ** 2).sum(axis=1).mean()) * 1e3:.2f}" for law in analytic]
            lines.append(f"| {lo * 1e3:.0f}-{hi * 1e3:.0f} | {rows.sum()} | "
                         f"{np.linalg.norm(fe_surface[rows], axis=1).mean() * 1e3:.2f} | " + " | ".join(cells) + " |")
    total = {law: np.sqrt((d ** 2).sum(axis=1).mean()) * 1e3 for law, d in differences.items()}
    lines += ["", f"Over the whole surface: RMS difference {total['linear']:.2f} mm (linear), "
              f"{total['stiffening']:.2f} mm (stiffening); largest FE displacement "
              f"{np.linalg.norm(fe_surface, axis=1).max() * 1e3:.2f} mm.", ""]
    lines += ["## 5. The paper's data on the FE tongue", "",
              "`softenv.fem.data.fe_paper_dataset` (8 cells a side; the paper's contact points, force straight "
              "down, 11 magnitudes up to 8 N, noise 1e-5 of the radius) against `softenv.datasets.paper_dataset` "
              "(analytic, linear law). Components kept by the scree test (the paper's) / the noise floor:", "",
              "| points | deformations | FE | analytic | FE generation (s) |", "|---|---|---|---|---|"]
    for n_points in (441, 961):
        t0 = time.perf_counter()
        fe_data = fe_paper_dataset(n_points, 10, 11, params=FEParams(cells_per_side=8), jobs=args.jobs, echo=None)
        seconds = time.perf_counter() - t0
        an_data = paper_dataset(n_points, 10, 11)
        for D in (1, 3, 5, 10):
            k = [[ShapeModel(rule, noise_std=d.noise_std).fit(d.shapes[d.contact_ids < D]).n_components_
                  for rule in ("scree", "noise")] for d in (fe_data, an_data)]
            lines.append(f"| {n_points} | {D} | {k[0][0]} / {k[0][1]} | {k[1][0]} / {k[1][1]} | "
                         f"{f'{seconds:.0f}' if D == 1 else ''} |")
    lines.append("")
    lines += regressor_section(args.seeds, args.jobs, Path(args.out))
    _plot(Path(args.out) / "fem_indentation.png", fe_forces, fe_depth, curves)
    command = "python " + " ".join(sys.argv)
    lines += [f"Made by `{command}` at {code_revision()} in {time.perf_counter() - started:.0f} s "
              f"({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}); plot: `fem_indentation.png`.", ""]
    Path(args.out).mkdir(parents=True, exist_ok=True)
    write_text(Path(args.out) / "fem.md", "\n".join(lines))
    print("\n".join(lines))


def regressor_section(seeds: int, jobs: int, out: Path) -> list[str]:
    """Section 6: the paper's regressors on FE and analytic paper data (441 and 961 points), the same
    evaluation for both, and their error against the haptic update time (``fem_error_vs_runtime.png``)."""
    from evaluate_regressors import evaluate_one        # this script's neighbour: one evaluation for both

    models = ["poly1", "poly2", "poly3", "anfis", "mlp"]
    rows = []
    for n_points in (441, 961):
        for seed in range(seeds):
            sources = {"FE": fe_paper_dataset(n_points, 10, 11, params=FEParams(cells_per_side=8), seed=seed, jobs=jobs,
                                              echo=None),
                       "analytic": paper_dataset(n_points, 10, 11, seed=seed)}
            for source, data in sources.items():
                for split_name in ("rows", "contacts"):
                    split = (split_rows(data.n_samples, seed=seed) if split_name == "rows"
                             else split_by_contact(data.contact_ids, seed=seed))
                    shape_model = ShapeModel("scree", noise_std=data.noise_std).fit(data.shapes[split.train], data.mesh)
                    for name in models:
                        row, _ = evaluate_one(name, data, split, shape_model, seed, quick=True)
                        rows.append(dict(row, source=source, split=split_name, points=n_points))

    def mean(name: str, points: int, source: str, split: str, key: str = "rmse_mm") -> float:
        return float(np.mean([r[key] for r in rows if r["model"] == name and r["points"] == points
                              and r["source"] == source and r["split"] == split]))

    lines = ["## 6. The paper's regressors on FE data", "",
             f"10 deformations x 11 magnitudes, {seeds} data seeds (mean over seeds); the shape model (scree) and the "
             "regressors are fitted on the training rows; surface RMSE of the decoded prediction on the test rows "
             "(mm) and the haptic update (predict + decode, us). Error against update time: "
             "`fem_error_vs_runtime.png`.", ""]
    for points in (441, 961):
        lines += [f"{points} points:", "",
                  "| model | FE, random rows | analytic, random rows | FE, held-out contacts | analytic, held-out "
                  "contacts | haptic update on FE (us) |", "|---|---|---|---|---|---|"]
        for name in models:
            lines.append(f"| {name} | {mean(name, points, 'FE', 'rows'):.3f} | {mean(name, points, 'analytic', 'rows'):.3f} "
                         f"| {mean(name, points, 'FE', 'contacts'):.3f} | {mean(name, points, 'analytic', 'contacts'):.3f} "
                         f"| {mean(name, points, 'FE', 'rows', 'haptic_us'):.0f} |")
        lines.append("")
    _plot_error_vs_runtime(out / "fem_error_vs_runtime.png", models, mean)
    return lines


def _plot_error_vs_runtime(path: Path, models: list[str], mean) -> None:
    """One marker shape per model, one colour per data source; filled: 441 points, hollow: 961."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    markers = dict(zip(models, "osD^v"))
    colours = {"FE": "tab:red", "analytic": "tab:blue"}
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.8), sharey=True)
    for ax, split in zip(axes, ("rows", "contacts")):
        for source, colour in colours.items():
            for points in (441, 961):
                for m in models:
                    ax.scatter(mean(m, points, source, split, "haptic_us"), mean(m, points, source, split),
                               marker=markers[m], s=36, edgecolors=colour,
                               facecolors=colour if points == 441 else "none")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("haptic update: predict + decode (us)")
        ax.set_title("random rows" if split == "rows" else "held-out contact points", fontsize=9)
    axes[0].set_ylabel("surface RMSE (mm)")
    handles = [Line2D([], [], ls="", marker=markers[m], color="k", label=m) for m in models]
    handles += [Line2D([], [], ls="", marker="o", color=c, label=f"{s} data") for s, c in colours.items()]
    handles += [Line2D([], [], ls="", marker="o", color="k", label="441 points"),
                Line2D([], [], ls="", marker="o", markerfacecolor="none", color="k", label="961 points")]
    fig.legend(handles=handles, loc="center right", fontsize=7, frameon=False)
    fig.tight_layout(rect=(0, 0, 0.84, 1))
    save_figure(fig, path, dpi=120)
    plt.close(fig)


def _plot(path: Path, forces: np.ndarray, fe_depth: np.ndarray, curves: dict[str, list[float]]) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5, 3.5))
    ax.plot(forces, fe_depth * 1e3, "o-", label="FE tongue (neo-Hookean, 8 cells a side)")
    for law, w in curves.items():
        ax.plot(forces, np.array(w) * 1e3, "--", label=f"analytic, {law}")
    ax.set_xlabel("force on the patch (N)")
    ax.set_ylabel("indentation of the top (mm)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, path, dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    main()
