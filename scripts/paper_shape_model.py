"""Reproduce the paper's shape-model claims (sections 4.1 and 4.3) and write results/paper_shape_model.md.

    python scripts/paper_shape_model.py [--out results]

1. Linear law, D = 1..10 deformations x 11 magnitudes, 441 and 961 points: the number of
   components each rule keeps (the paper: the scree test keeps D, at both resolutions).
2. Each component at 441 points against the same component at 961 points (|correlation| of the
   displacement fields, 961-point field interpolated onto the 441 points).
3. Reconstruction error against the noise level (the paper: errors "of rank 1e-5").
4. Stiffening (nonlinear) law: what each rule keeps, and reconstruction error against k.
5. Figures: scree plots, components 1-3 of a 4-deformation model (the paper's Fig. 4.1) and a
   10-deformation complex shape (Fig. 4.2).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
os.environ.setdefault("MPLBACKEND", "Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from softenv._artifact import save_figure, write_text  # noqa: E402
from softenv.datasets import paper_dataset  # noqa: E402
from softenv.geometry import interpolate_latlong  # noqa: E402
from softenv.render import View, displacement_colorbar, draw_surface  # noqa: E402
from softenv.scree import cattell_scree  # noqa: E402
from softenv.shape_model import ShapeModel  # noqa: E402
from softenv.bench.timing import code_revision  # noqa: E402

EXAGGERATE = 3.0  # figures scale displacements for visibility (stated in their titles)
FIG41_TOP = 0.003  # Fig. 4.1's colour scale ends at 3 mm: every component's extremes fall under it
RULES = ["scree", "kneedle", "noise", "variance_0.99", "variance_0.999"]


def rule_table(law: str) -> tuple[list[str], dict]:
    lines = ["| D | points | " + " | ".join(RULES) + " |", "|---" * (len(RULES) + 2) + "|"]
    picks = {}
    for D in range(1, 11):
        for n in (441, 961):
            d = paper_dataset(n, n_deformations=D, law=law)
            m = ShapeModel("scree", noise_std=d.noise_std).fit(d.shapes, d.mesh)
            picks[(D, n)] = m.picks_
            lines.append(f"| {D} | {n} | " + " | ".join(str(m.picks_[r]) for r in RULES) + " |")
    return lines, picks


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="results")
    out = Path(parser.parse_args().out)
    out.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    md = ["# The paper's shape-model claims, reproduced", "",
          f"Made by `python scripts/paper_shape_model.py --out {out}` at {code_revision()}. Data: `softenv.paper_dataset` "
          "(contact points spread over the dorsum within 30 deg of the top, force straight down, magnitudes "
          "8 N x (1..11)/11, white noise 1e-5 of the radius unless stated; sphere radius 30 mm).", ""]

    # 1. number of components by rule, linear law
    lines, picks = rule_table("linear")
    hits = sum(picks[(D, n)]["scree"] == D for D in range(1, 11) for n in (441, 961))
    md += ["## 1. Components kept, linear law (paper: the scree test keeps one per deformation)", "",
           f"The scree test keeps k = D in **{hits} of 20** cases (D = 1..10 at 441 and 961 points); so does the "
           "noise-floor rule. Kneedle on the raw eigenvalues and variance fractions stop early, as DESIGN.md "
           "warned: the eigenvalues of different contact points differ by an order of magnitude.", ""] + lines + [""]

    # 2. component correspondence between resolutions
    md += ["## 2. Each component moves the surface the same way at 441 and 961 points", "",
           "The absolute correlation between component i of the 441-point model and component i of the 961-point model "
           "(interpolated onto the 441 points); and the ratio of their eigenvalues (sums over points: "
           "expected 441/961 = 0.459).", "", "| D | abs(correlation) per component | eigenvalue ratio |", "|---|---|---|"]
    for D in (4, 10):
        a, b = paper_dataset(441, n_deformations=D), paper_dataset(961, n_deformations=D)
        ma, mb = ShapeModel("scree").fit(a.shapes, a.mesh), ShapeModel("scree").fit(b.shapes, b.mesh)
        cors = [abs(np.corrcoef(ma.components_[i], interpolate_latlong(mb.components_[i], 31, a.mesh.vertices).ravel())[0, 1])
                for i in range(D)]
        ratio = ma.explained_variance_ / mb.explained_variance_
        md.append(f"| {D} | {', '.join(f'{c:.4f}' for c in cors)} | {ratio.min():.3f}-{ratio.max():.3f} |")
    md.append("")

    # 3. reconstruction error against noise
    md += ["## 3. Reconstruction error against noise (paper: errors of rank 1e-5)", "",
           "961 points, 10 deformations. RMSE per coordinate, relative to the radius; *vs data* compares with "
           "the noisy shapes, *vs truth* with the noise-free ones. What remains against the truth is the "
           "noise's projection on the mean and the k components, sigma sqrt((k+1)/n).", "",
           "| noise sigma / R | k (scree) | RMSE vs data / R | RMSE vs truth / R | sigma sqrt((k+1)/n) / R |",
           "|---|---|---|---|---|"]
    clean = paper_dataset(961, noise=0.0)
    R = clean.tissue.radius
    for sigma in (1e-6, 1e-5, 1e-4, 1e-3):
        d = paper_dataset(961, noise=sigma)
        m = ShapeModel("scree").fit(d.shapes, d.mesh)
        rec = m.reconstruct(d.shapes)
        e_data = np.sqrt(np.mean((rec - d.shapes) ** 2)) / R
        e_true = np.sqrt(np.mean((rec - clean.shapes) ** 2)) / R
        md.append(f"| {sigma:.0e} | {m.n_components_} | {e_data:.2e} | {e_true:.2e} | "
                  f"{sigma * np.sqrt((m.n_components_ + 1) / d.n_samples):.2e} |")
    md.append("")

    # 4. the stiffening law
    lines, picks_nl = rule_table("stiffening")
    md += ["## 4. Stiffening (nonlinear) law", "",
           "With Fung stiffening and Hertzian widening of the contact, a deformation's shape changes with its "
           "magnitude, so each contact point needs more than one component (DESIGN.md's prediction). "
           "What each rule keeps:", ""] + lines + [""]
    d = paper_dataset(961, law="stiffening")
    full = ShapeModel(min(60, d.n_samples - 1)).fit(d.shapes, d.mesh)
    ks = np.arange(1, 41)
    errs = []
    for k in ks:
        b = full.encode(d.shapes)[:, :k]
        rec = full.mean_ + b @ full.components_[:k]
        errs.append(np.sqrt(np.mean((rec - d.shapes) ** 2)) / R)
    md += ["Reconstruction RMSE / R against k (10 deformations, 961 points, noise 1e-5 R): " +
           ", ".join(f"k={k}: {e:.1e}" for k, e in zip(ks, errs) if k in (1, 5, 10, 15, 20, 25, 30, 40)),
           "", "![error against k](paper_nonlinear_error_vs_k.png)", ""]
    fig, ax = plt.subplots(figsize=(5, 3.2))
    ax.semilogy(ks, errs, "o-", ms=3)
    ax.axhline(1e-5, color="0.5", ls="--", label="noise level")
    ax.axvline(picks_nl[(10, 961)]["scree"], color="C3", ls=":", label="scree k")
    ax.set_xlabel("k (components kept)")
    ax.set_ylabel("RMSE / radius")
    ax.set_title("stiffening law, 10 deformations, 961 points", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, out / "paper_nonlinear_error_vs_k.png", dpi=120)
    plt.close(fig)

    # 5a. scree plots
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.4))
    for ax, law in zip(axes, ("linear", "stiffening")):
        for D in (2, 4, 10):
            lam = ShapeModel(1).fit(paper_dataset(961, n_deformations=D, law=law).shapes).spectrum_[:40]
            k = cattell_scree(lam)
            ax.semilogy(np.arange(1, lam.size + 1), lam, "o-", ms=3, label=f"D={D}: scree k={k}")
        ax.set_xlabel("component")
        ax.set_ylabel("eigenvalue (m^2)")
        ax.set_title(f"{law} law, 961 points", fontsize=9)
        ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, out / "paper_scree.png", dpi=120)
    plt.close(fig)

    # 5b. Fig. 4.1: components 1-3 of a four-deformation model, each varied over its data range
    d = paper_dataset(441, n_deformations=4)
    m = ShapeModel("scree").fit(d.shapes, d.mesh)
    view = View(elevation=35, azimuth=-60)
    rest = d.mesh.vertices
    fig, axes = plt.subplots(3, 3, figsize=(7, 7.6), layout="constrained")
    for i in range(3):
        for j, level in enumerate((m.b_min_[i], 0.0, m.b_max_[i])):
            b = np.zeros(m.n_components_)
            b[i] = level
            pts = m.decode(b).reshape(-1, 3)
            shown = rest + EXAGGERATE * (pts - rest)
            draw_surface(axes[i, j], shown, d.mesh.triangles, np.linalg.norm(pts - rest, axis=1), view=view,
                         vmin=0, vmax=FIG41_TOP, title=f"b{i + 1} = {level * 1e3:+.2f} mm")
    displacement_colorbar(fig, axes, R, top=FIG41_TOP, orientation="horizontal", shrink=0.6, aspect=40,
                          label="displacement (mm, before the x3 drawn)")
    fig.suptitle(f"Components 1-3 of a four-deformation model (cf. the paper's Fig. 4.1); "
                 f"displacements drawn x{EXAGGERATE:g}", fontsize=10)
    save_figure(fig, out / "paper_fig4_1_components.png", dpi=110)
    plt.close(fig)

    # 5c. Fig. 4.2: a complex shape combining the ten deformations
    d = paper_dataset(441, n_deformations=10)
    m = ShapeModel("scree").fit(d.shapes, d.mesh)
    surfaces = d.shapes.reshape(10, 11, -1)[:, -1]               # each deformation at full force
    combined = rest.ravel() + (surfaces - rest.ravel()).sum(axis=0)   # superposition (linear law)
    b = m.encode(combined)
    pts = m.decode(b).reshape(-1, 3)
    moved = np.linalg.norm(pts - rest, axis=1)
    fig, axes = plt.subplots(1, 2, figsize=(7, 4.4), layout="constrained")
    for ax, v in zip(axes, (View(35, -60), View(80, -90))):
        draw_surface(ax, rest + EXAGGERATE * (pts - rest), d.mesh.triangles, moved, view=v, vmin=0, vmax=float(moved.max()))
    displacement_colorbar(fig, axes, R, top=float(moved.max()), orientation="horizontal", shrink=0.6, aspect=40,
                          label="displacement (mm, before the x3 drawn)")
    fig.suptitle("Ten deformations combined, rebuilt from 10 shape parameters (cf. Fig. 4.2); "
                 f"displacements drawn x{EXAGGERATE:g}", fontsize=9)
    save_figure(fig, out / "paper_fig4_2_complex.png", dpi=110)
    plt.close(fig)
    err = np.sqrt(np.mean((m.decode(b) - combined) ** 2)) / R
    md += ["## 5. Figures", "", "![scree](paper_scree.png)", "",
           "![components 1-3](paper_fig4_1_components.png)", "",
           f"The ten-deformation shape is rebuilt from its 10 shape parameters with RMSE {err:.1e} R, which is the "
           f"noise carried by the ten summed noisy samples (sqrt(10) x {d.noise:.0e} = {np.sqrt(10) * d.noise:.1e}): "
           "the superposition of the deformations lies in the model's subspace.", "",
           "![complex shape](paper_fig4_2_complex.png)", "",
           f"_Generated in {time.perf_counter() - started:.0f} s with numpy {np.__version__}, "
           f"Python {sys.version.split()[0]}._", ""]
    write_text(out / "paper_shape_model.md", "\n".join(md))
    print(f"wrote {out / 'paper_shape_model.md'}")


if __name__ == "__main__":
    main()
