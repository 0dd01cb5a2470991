"""``softenv bench``: the machine facts it records (which OpenBLAS kernels ran), its advice, its reports."""

import json
import os
import platform
import re
import subprocess
import sys

import numpy as np
import pytest

from softenv import bench
from softenv.bench import timing

OPENBLAS = "openblas" in np.show_config(mode="dicts")["Build Dependencies"]["blas"]["name"].lower()


AVX512 = set(timing.AVX512_FLAGS) <= set(timing._cpuinfo().get("flags", "").split())


@pytest.mark.skipif(not OPENBLAS or platform.machine() != "x86_64", reason="reads x86-64 OpenBLAS kernel names")
@pytest.mark.parametrize("coretype, small_gemm", [
    ("Sandybridge", False), ("Haswell", False),
    pytest.param("SkylakeX", True, marks=pytest.mark.skipif(not AVX512, reason="this CPU has no AVX-512")),
])
def test_openblas_kernels_names_the_kernels_openblas_loaded(coretype, small_gemm):
    # a fresh interpreter, so that OpenBLAS reads OPENBLAS_CORETYPE when numpy loads it
    env = {**os.environ, "OPENBLAS_CORETYPE": coretype}
    code = "from softenv._blas import openblas_kernels, has_small_gemm; print(openblas_kernels(), has_small_gemm())"
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.split() == [coretype, str(small_gemm)]


def test_blas_advice_only_for_avx2_kernels_on_an_avx512_cpu(monkeypatch):
    avx512 = {"flags": "fpu sse avx avx2 fma " + " ".join(timing.AVX512_FLAGS)}
    monkeypatch.setattr(timing, "_cpuinfo", lambda: avx512)
    monkeypatch.delenv("OPENBLAS_CORETYPE", raising=False)
    monkeypatch.setattr(timing, "openblas_kernels", lambda: "SkylakeX")
    assert timing.blas_advice() is None
    monkeypatch.setattr(timing, "openblas_kernels", lambda: "Haswell")
    assert "set OPENBLAS_CORETYPE=SkylakeX" in timing.blas_advice()
    monkeypatch.setenv("OPENBLAS_CORETYPE", "Haswell")  # a pin: name it and how to lift it
    advice = timing.blas_advice()
    assert "OPENBLAS_CORETYPE=Haswell pins" in advice and "env -u OPENBLAS_CORETYPE" in advice
    monkeypatch.setattr(timing, "_cpuinfo", lambda: {"flags": "fpu sse avx avx2 fma"})  # AVX2 is all there is
    assert timing.blas_advice() is None


def test_steadiness_names_a_host_whose_speed_moved_during_the_run():
    steady = timing.Timing(np.array([1.00, 1.01, 1.02, 1.03]) * 1e-5)
    assert bench.steadiness(steady, steady) is None
    # a spread like this session's busy VM (CartPole's IQR 44,050-66,189 steps/s about 45,465)
    spread = timing.Timing(np.array([1.0, 1.0, 1.5, 1.5, 2.0]) * 1e-5)
    assert "spread 33%" in bench.steadiness(spread, spread)      # (1.5 - 1.0) / 1.5
    # steady within each timing, but 25 % slower at the end: the rate changed -20 %
    slower = timing.Timing(steady.samples * 1.25)
    warning = bench.steadiness(steady, slower)
    assert warning is not None and "changed -20%" in warning and "within 10%" in warning
    assert bench.steadiness(steady, timing.Timing(steady.samples * 1.05)) is None


def test_command_line_states_the_openblas_kernel_setting(monkeypatch):
    monkeypatch.setenv("OPENBLAS_CORETYPE", "Haswell")
    assert bench.command_line(["bench", "--quick"]) == "OPENBLAS_CORETYPE=Haswell softenv bench --quick"
    monkeypatch.delenv("OPENBLAS_CORETYPE")
    assert bench.command_line(["bench"]) == "env -u OPENBLAS_CORETYPE softenv bench"


def test_bench_run_writes_reports_with_machine_facts(tmp_path):
    lines = []
    rows = bench.run(True, tmp_path, ["fit"], command="softenv bench --quick --only fit", echo=lines.append)
    assert rows[0].section == "reference" and rows[0].value > 0
    fit = [r for r in rows if r.section == "shape model"]
    assert fit and all(r.value > 0 for r in fit)
    payload = json.loads((tmp_path / "perf_quick.json").read_text())
    assert payload["machine"]["openblas_kernels"] == timing.openblas_kernels()
    assert payload["machine"]["OPENBLAS_CORETYPE"] == os.environ.get("OPENBLAS_CORETYPE", "unset")
    assert payload["blas_advice"] == timing.blas_advice()
    # the reference is timed at the start and at the end; a host whose speed moved between them is named
    assert [r.section for r in (rows[0], rows[-1])] == ["reference", "reference"] and rows[-1].value > 0
    assert "unsteady_host" in payload and (payload["unsteady_host"] is None) == ("Warning: this host" not in (tmp_path / "perf_quick.md").read_text())
    assert payload["code"] == timing.code_revision()
    md = (tmp_path / "perf_quick.md").read_text()
    assert f"softenv bench --quick --only fit` at {payload['code']} in" in md and "| shape model | fit, paper data" in md
    with pytest.raises(ValueError, match="unknown bench section"):
        bench.run(True, tmp_path, ["nope"])


def _git(root, *args):
    return subprocess.run(["git", "-C", str(root), "-c", "user.name=t", "-c", "user.email=t@example.org", *args],
                          check=True, capture_output=True, text=True).stdout.strip()


def test_code_revision_names_the_commit_and_code_changes_only(tmp_path):
    import softenv

    outside = f"softenv {softenv.__version__} (not a git checkout)"
    assert timing.code_revision(tmp_path) == outside
    (tmp_path / "softenv").mkdir()
    (tmp_path / "softenv" / "step.py").write_text("x = 1\n")
    (tmp_path / "README.md").write_text("docs\n")
    _git(tmp_path, "init", "-q")
    _git(tmp_path, "add", "-A")
    _git(tmp_path, "commit", "-qm", "first")
    head = _git(tmp_path, "rev-parse", "--short=12", "HEAD")
    assert timing.code_revision(tmp_path) == f"git {head}"
    (tmp_path / "README.md").write_text("other docs\n")           # docs and results do not change numbers
    (tmp_path / "notes.txt").write_text("a new file outside the code\n")
    assert timing.code_revision(tmp_path) == f"git {head}"
    (tmp_path / "softenv" / "step.py").write_text("x = 2\n")
    assert timing.code_revision(tmp_path) == f"git {head} + uncommitted changes"
    _git(tmp_path, "checkout", "-q", "--", "softenv/step.py")
    (tmp_path / "softenv" / "new.py").write_text("y = 2\n")        # a new module may be imported
    assert timing.code_revision(tmp_path) == f"git {head} + uncommitted changes"
    # a package inside someone else's repository (a venv in a checkout): that commit is not the package's
    assert timing.code_revision(tmp_path / "softenv") == outside


def test_the_pinned_allocator_row_times_the_twin_in_a_child_with_the_threshold_pinned():
    from softenv.bench.env import _pinned_allocator_row

    row = _pinned_allocator_row(64, 5, free_rate=1.0)
    if platform.libc_ver()[0] != "glibc":
        assert np.isnan(row.value) and "glibc" in row.spread
        return
    assert row.value > 0 and row.unit == "env-steps/s"
    assert re.fullmatch(r"\d+ page faults a step; [\d.]+x the run above", row.spread), row.spread


def test_the_gradients_section_times_an_episode_backward_and_its_graph_on_both_devices():
    """``softenv bench --only gradients`` (quick sizes): each device kind's backward pass over its forward step,
    measured in a fresh process, and the memory its graph holds."""
    from softenv.bench.gradients import bench_gradients

    rows = bench_gradients(True, None)
    assert [r.metric.split(":")[0] for r in rows] == ["SoftSphere-v0"] * 2 + ["SoftSphereHaptic-v0"] * 2
    for r in rows:
        assert np.isfinite(r.value) and r.value > 0, r
    ratio, memory = rows[0], rows[1]
    assert ratio.unit == "x the forward step" and ratio.target == "<= 3x" and ratio.ok == (ratio.value <= 3.0)
    assert memory.unit == "MB" and "KB an env-step" in memory.spread


@pytest.mark.slow
def test_the_speed_comparison_script_times_both_trees_side_by_side(tmp_path):
    """``scripts/speed_against.py`` against this very commit (a worktree of HEAD): a row per workload and
    size, each side's rate the median of its rounds, the ratio theirs, a fresh process's first step with
    Warp's kernel cache warm and empty, the reference's commit named, and the temporary worktree gone
    afterwards."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    done = subprocess.run([sys.executable, "scripts/speed_against.py", "--ref", "HEAD", "--rounds", "1",
                           "--sizes", "8", "--out", str(tmp_path)], cwd=root, capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    data = json.loads((tmp_path / "results.json").read_text())
    head = subprocess.run(["git", "-C", root, "rev-parse", "--short=12", "HEAD"], capture_output=True,
                          text=True, check=True).stdout.strip()
    assert data["reference_commit"] == head
    assert [(r["workload"], r["envs"]) for r in data["rows"]] == [("random", 8), ("pressing", 8)]
    for row in data["rows"]:
        assert len(row["reference"]) == len(row["this_commit"]) == 1 and min(row["reference"]) > 0
        assert row["ratio"] == pytest.approx(np.median(row["this_commit"]) / np.median(row["reference"]))
    assert f"| random | 8 | {np.median(data['rows'][0]['reference']):,.0f} |" in (tmp_path / "README.md").read_text()
    starts = data["first_step_s"]         # a fresh process's first step, Warp's kernel cache warm and empty
    assert sorted(starts) == ["empty", "warm"]
    for cache, by_tree in starts.items():
        assert sorted(by_tree) == ["reference", "this commit"] and all(len(t) == 1 and min(t) > 0 for t in by_tree.values())
        row = f"| {cache} | {np.median(by_tree['reference']):.2f} | {np.median(by_tree['this commit']):.2f} |"
        assert row in (tmp_path / "README.md").read_text()
    worktrees = subprocess.run(["git", "-C", root, "worktree", "list"], capture_output=True, text=True).stdout
    assert "reference" not in worktrees
    bad = subprocess.run([sys.executable, "scripts/speed_against.py", "--rounds", "0"], cwd=root,
                         capture_output=True, text=True)
    assert bad.returncode != 0 and "--rounds 0: at least 1" in bad.stderr
