"""Test set-up: one BLAS/torch thread (2-core CI machines, one test process a core) and an isolated cache directory."""

import collections
import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
os.environ.setdefault("MPLBACKEND", "Agg")

import shutil  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402

import pytest  # noqa: E402
from hypothesis import HealthCheck, settings  # noqa: E402

# hypothesis profiles for every property test: "ci" (the default) and "long" (SOFTENV_HYPOTHESIS_PROFILE=long)
_COMMON = {"deadline": None, "suppress_health_check": [HealthCheck.too_slow, HealthCheck.data_too_large],
           "derandomize": True, "print_blob": True}
settings.register_profile("ci", max_examples=60, **_COMMON)
settings.register_profile("long", max_examples=1_000, **_COMMON)
settings.load_profile(os.environ.get("SOFTENV_HYPOTHESIS_PROFILE", "ci"))

# one cache a test run, made by the first pytest process and inherited by pytest -n's workers (writes are atomic);
# the process that made it removes it at the end
_OWNS_CACHE = "SOFTENV_TEST_RUN_CACHE" not in os.environ
if _OWNS_CACHE:
    os.environ["SOFTENV_TEST_RUN_CACHE"] = tempfile.mkdtemp(prefix="softenv-test-cache-")
_CACHE = os.environ["SOFTENV_CACHE_DIR"] = os.environ["SOFTENV_TEST_RUN_CACHE"]
# stable-baselines3's default logger makes an empty folder a learn() call in the system's temp directory
os.environ.setdefault("SB3_LOGDIR", os.path.join(_CACHE, "sb3-logs"))

try:  # torch is an optional extra; when present, keep it to one thread as well
    import torch

    torch.set_num_threads(1)
except ImportError:  # pragma: no cover
    pass


# cases tried per input class (scripts/stability.py runs the hostile-input tests and tabulates these)
TRIED: "collections.Counter[str]" = collections.Counter()


def pytest_configure(config: pytest.Config) -> None:
    if hasattr(config.option, "loadscopereorder"):
        config.option.loadscopereorder = False          # pytest-xdist deals the files in the order below


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Files holding a ``slow`` test first, then the rest by their number of tests (pytest-xdist's own order,
    which it keeps to when told not to reorder): with ``--dist loadfile`` a long file dealt last runs alone
    at the end (about 90 s of a 2-core run, by scheduling one run's JUnit times both ways)."""
    by_file: dict[object, list[pytest.Item]] = {}
    for item in items:
        by_file.setdefault(item.path, []).append(item)

    def order(tests: list[pytest.Item]) -> tuple[bool, int]:
        return not any(t.get_closest_marker("slow") for t in tests), -len(tests)

    items[:] = [item for tests in sorted(by_file.values(), key=order) for item in tests]


def pytest_unconfigure(config: pytest.Config) -> None:
    if _OWNS_CACHE:
        shutil.rmtree(_CACHE, ignore_errors=True)


@pytest.fixture(scope="session")
def tried() -> "collections.Counter[str]":
    """Count a case of an input class: ``tried["class"] += 1``."""
    return TRIED


@pytest.fixture(scope="session")
def cache_dir() -> str:
    return _CACHE


HEAVY_MODULES = ("pymunk", "warp", "numba", "matplotlib", "torch", "scipy", "felupe")


@pytest.fixture(scope="session")
def heavy_modules_after(cache_dir):
    """Run Python ``code`` in a fresh interpreter (softenv not imported first); return which of
    ``HEAVY_MODULES`` it loaded, sorted."""
    def run(code: str) -> list[str]:
        probe = f"\nimport sys\nprint(sorted(m for m in {HEAVY_MODULES!r} if m in sys.modules))\n"
        out = subprocess.run([sys.executable, "-c", code + probe], capture_output=True, text=True, check=True)
        return eval(out.stdout.strip().splitlines()[-1])
    return run


@pytest.fixture
def scene_makes(monkeypatch):
    """Every scene config made from here on (``make_config``, from the config module or the scoring's import)."""
    import softenv.envs.config as config_module
    from softenv.training import scoring

    made, real = [], config_module.make_config

    def counting(*args, **kwargs):
        made.append(args)
        return real(*args, **kwargs)

    monkeypatch.setattr(config_module, "make_config", counting)
    monkeypatch.setattr(scoring, "make_config", counting)
    return made
