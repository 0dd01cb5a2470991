"""The house's rules on imports: the layers of pyproject.toml hold (import-linter, imports inside
functions included), and an import inside a function is only there to keep an optional dependency out
of the processes that do not need it, saying so in a comment."""

import ast
import re
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("softenv",)     # softenv/baselines links the repository's baselines/ into the package
# what an extra (or the platform) brings: the only reasons to import inside a function
OPTIONAL = {"pymunk", "torch", "matplotlib", "felupe", "ray", "pygame", "stable_baselines3", "yaml", "scipy",
            "tensorboard", "rich", "tqdm", "torchrl", "resource", "pyOpenHaptics", "forcedimension_core",
            "triton", "warp", "minari", "sqlalchemy", "alembic", "starlette", "starlette_csrf", "uvicorn", "PIL"}


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def absolute(node: ast.ImportFrom | ast.Import, importer: str, is_package: bool) -> list[str]:
    if isinstance(node, ast.Import):
        return [alias.name for alias in node.names]
    if not node.level:
        return [node.module or ""]
    base = importer.split(".")
    base = base if is_package else base[:-1]
    base = base[:len(base) - (node.level - 1)]
    stem = ".".join(base + ([node.module] if node.module else []))
    return [stem] if node.module else [f"{stem}.{alias.name}" for alias in node.names]


def sources() -> dict[str, tuple[Path, ast.Module]]:
    out = {}
    for package in PACKAGES:
        for folder, _, files in os.walk(ROOT / package, followlinks=True):     # softenv/baselines is a link
            for path in (Path(folder) / name for name in files if name.endswith(".py")):
                out[module_name(path)] = (path, ast.parse(path.read_text()))
    return out


def module_level_imports(tree: ast.Module, name: str, is_package: bool) -> set[str]:
    """What a module imports when it loads: every import not inside a function (try blocks included)."""
    found: set[str] = set()

    def visit(node: ast.AST) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
                continue
            if isinstance(child, (ast.Import, ast.ImportFrom)):
                found.update(absolute(child, name, is_package))
            visit(child)
    visit(tree)
    return found


def reaches_optional(target: str, modules: dict, seen: set[str]) -> bool:
    """Whether loading ``target`` (and what it loads, within the house) loads an optional dependency."""
    if target.split(".")[0] in OPTIONAL:
        return True
    candidates = [m for m in (target, target.rpartition(".")[0]) if m in modules]
    for name in candidates:
        if name in seen:
            continue
        seen.add(name)
        path, tree = modules[name]
        if any(reaches_optional(t, modules, seen) for t in module_level_imports(tree, name, path.name == "__init__.py")):
            return True
    return False


def test_the_layers_hold():
    lint = shutil.which("lint-imports") or str(Path(sys.executable).with_name("lint-imports"))
    done = subprocess.run([lint, "--config", str(ROOT / "pyproject.toml")], cwd=ROOT, capture_output=True, text=True)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-2000:]
    assert "1 kept, 0 broken" in done.stdout


def test_an_import_inside_a_function_keeps_an_optional_dependency_out_and_says_so():
    modules = sources()
    offenders = []
    for name, (path, tree) in modules.items():
        lines = path.read_text().splitlines()
        for fn in ast.walk(tree):
            if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            for node in ast.walk(fn):
                if not isinstance(node, (ast.Import, ast.ImportFrom)):
                    continue
                where = f"{path.relative_to(ROOT)}:{node.lineno}"
                targets = absolute(node, name, path.name == "__init__.py")
                if not all(reaches_optional(t, modules, set()) for t in targets):
                    offenders.append(f"{where}: {targets} loads no optional dependency: import it at the top")
                elif "#" not in lines[node.lineno - 1]:
                    offenders.append(f"{where}: say in a comment which optional dependency this keeps out")
    assert not offenders, "\n".join(offenders)


@pytest.mark.parametrize("bad", ["from .envs import world", "import numpy"])
def test_the_import_rule_catches_what_it_should(bad, tmp_path):
    """The checker itself: a function that imports a layer above, or a core dependency, is caught."""
    tree = ast.parse(f"def f():\n    {bad}  # a comment is not enough\n")
    node = next(n for n in ast.walk(tree) if isinstance(n, (ast.Import, ast.ImportFrom)))
    targets = absolute(node, "softenv.tissue", False)
    assert not all(reaches_optional(t, sources(), set()) for t in targets)


def test_nothing_imports_the_top_level_name_baselines():
    """The baselines are softenv.baselines: in a checkout the folder is importable as `baselines` too, and
    one module under two names would be two modules (and a name that collides with OpenAI Baselines')."""
    offenders = []
    tracked = subprocess.run(["git", "ls-files", "*.py", "*.md"], cwd=ROOT, capture_output=True, text=True, check=True)
    history = ("results/", "CHANGELOG.md", "tests/test_layers.py")     # records of commands as they were run
    for path in (ROOT / name for name in tracked.stdout.splitlines() if not name.startswith(history)):
        if not path.is_file() or path.is_symlink():
            continue
        for number, line in enumerate(path.read_text().splitlines(), 1):
            if re.search(r"^\s*(from|import) baselines\b|python -m baselines\b", line):
                offenders.append(f"{path.relative_to(ROOT)}:{number}: {line.strip()}")
    assert not offenders, "\n".join(offenders)
    assert (ROOT / "softenv" / "baselines").resolve() == (ROOT / "baselines").resolve()
