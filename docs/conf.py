"""Sphinx configuration: MyST pages, the furo theme, and pages generated from the code at each build
(one per env id from the env class's docstring and the id's scene, the settings table from the
config schema, and the leaderboard from ``results/leaderboard/*.json``, each file checked as
``softenv leaderboard check`` checks it), written to ``docs/_generated`` (ignored by git) so they never
drift from the code or the results."""

from __future__ import annotations

import importlib
import inspect
import re
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
sys.path.insert(0, str(DOCS.parent))

import gymnasium as gym  # noqa: E402

import softenv  # noqa: E402
from softenv import leaderboard, provenance  # noqa: E402
from softenv.airway import grade_table  # noqa: E402
from softenv.envs import ENV_SCENES, HAPTIC_SCENES  # noqa: E402
from softenv.envs.single import SoftSphereEnv  # noqa: E402

project = "softenv"
release = softenv.__version__
extensions = ["myst_parser"]
source_suffix = {".md": "markdown"}
exclude_patterns = ["_build"]
html_theme = "furo"
html_title = f"softenv {release}"
myst_heading_anchors = 3
# the API reference: the public objects, each with its signature and docstring (written in Markdown)
API = {
    "Environments": ["softenv.envs.single.SoftSphereEnv.reset", "softenv.envs.single.SoftSphereEnv.step",
                     "softenv.envs.world.World.compute_reward", "softenv.envs.vector.SoftSphereVectorEnv",
                     "softenv.envs.sb3.SoftSphereSB3VecEnv", "softenv.envs.wrappers.NumpyInfo",
                     "softenv.make_config", "softenv.describe_config", "softenv.default_config"],
    "Devices": ["softenv.devices.base.Device", "softenv.devices.base.DeviceBatch", "softenv.devices.base.DeviceKind",
                "softenv.devices.base.device_kind"],
    "Shape models and regressors": ["softenv.ShapeModel", "softenv.ShapeModel.fit", "softenv.ShapeModel.encode",
                                    "softenv.ShapeModel.decode", "softenv.paper_dataset", "softenv.ForceShapeData",
                                    "softenv.response.make_response"],
    "The haptic loop and trainee scoring": ["softenv.haptics.loop.HapticLoop", "softenv.haptics.loop.HapticLoop.tick",
                                            "softenv.haptics.loop.HapticLoop.surface",
                                            "softenv.training.scoring.score_file",
                                            "softenv.training.scoring.points_to_gain",
                                            "softenv.training.scoring.improvements",
                                            "softenv.training.logs.save_log", "softenv.training.logs.read_scene",
                                            "softenv.training.play.run", "softenv.training.inputs.InputDevice",
                                            "softenv.training.inputs.PygameInput",
                                            "softenv.training.inputs.ArmInput",
                                            "softenv.haptics.arms.ServoDevice",
                                            "softenv.haptics.bridge.BridgeServer",
                                            "softenv.haptics.bridge.BridgeClient",
                                            "softenv.haptics.render_force"],
    "Fan-out": ["softenv.parallel.run_jobs", "softenv.parallel.Job", "softenv.parallel.Interrupted",
                "softenv.parallel.stop_on_signals"],
    "Evaluation and the leaderboard": ["softenv.evaluation.evaluate_policy", "softenv.evaluation.Evaluation",
                                       "softenv.evaluation.aggregate", "softenv.evaluation.as_policy",
                                       "softenv.evaluation.score_aggregates",
                                       "softenv.leaderboard.result_record", "softenv.leaderboard.save_result",
                                       "softenv.leaderboard.read_result", "softenv.leaderboard.check_result",
                                       "softenv.leaderboard.load_results", "softenv.leaderboard.table",
                                       "softenv.baselines.anchors.load_anchors"],
    "Statistics": ["softenv.stats.iqm", "softenv.stats.optimality_gap", "softenv.stats.interval_estimates",
                   "softenv.stats.nested_interval", "softenv.stats.performance_profile",
                   "softenv.stats.profile_intervals", "softenv.stats.probability_of_improvement",
                   "softenv.stats.improvement_interval"],
    "Provenance of results": ["softenv.provenance.check", "softenv.provenance.lock", "softenv.provenance.coverage",
                              "softenv.provenance.read_manifest", "softenv.provenance.read_stamp",
                              "softenv.provenance.Freshness", "softenv.provenance.table"],
    "Baselines and agents": ["softenv.baselines.agents.train_agent", "softenv.baselines.agents.load_agent",
                             "softenv.baselines.evaluate.evaluate", "softenv.baselines.evaluate.normalized_scores",
                             "softenv.baselines.benchmark.run"],
    "Offline datasets and learners": ["softenv.baselines.minari_datasets.make_dataset",
                                      "softenv.baselines.minari_datasets.load_or_make",
                                      "softenv.baselines.minari_datasets.dataset_id",
                                      "softenv.baselines.minari_datasets.softenv_metadata",
                                      "softenv.baselines.minari_datasets.reference_returns",
                                      "softenv.baselines.offline.train", "softenv.baselines.offline.OfflineArgs",
                                      "softenv.baselines.offline.OfflinePolicy", "softenv.baselines.offline.save",
                                      "softenv.baselines.offline.load"],
    "Skills lab": ["softenv.skills.store.Store", "softenv.skills.store.StoredSession",
                   "softenv.skills.store.TraineeSummary", "softenv.skills.passmark.contrasting_groups",
                   "softenv.skills.passmark.crossing", "softenv.skills.passmark.PassMark",
                   "softenv.skills.cohort.build", "softenv.skills.cohort.demo_store", "softenv.skills.web.make_app"],
}


def markdown(doc: str, demote: bool = False) -> str:
    """A docstring as MyST: reST's double backticks and Python roles become code; with ``demote``, its
    own headings become bold lines (under an API entry's heading)."""
    text = inspect.cleandoc(doc)
    text = re.sub(r":(?:mod|class|func|meth|attr|data):`~?([^`]+)`", r"`\1`", text)
    text = text.replace("``", "`")
    return re.sub(r"(?m)^#+ (.+)$", r"**\1**", text) if demote else text


def resolve(dotted: str) -> object:
    parts = dotted.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        for name in parts[i:]:
            obj = getattr(obj, name)
        return obj
    raise ImportError(dotted)


def api_page() -> str:
    lines = ["# API reference\n", "The public objects, each with its signature and docstring, generated at each build.\n"]
    for section, names in API.items():
        lines.append(f"## {section}\n")
        for dotted in names:
            obj = resolve(dotted)
            try:
                signature = str(inspect.signature(obj))          # type: ignore[arg-type]
            except (TypeError, ValueError):
                signature = ""
            kind = "class" if inspect.isclass(obj) else "def"
            lines += [f"### `{dotted}`\n", "```python", f"{kind} {dotted.rsplit('.', 1)[1]}{signature}", "```\n",
                      markdown(inspect.getdoc(obj) or "(no docstring)", demote=True), ""]
    return "\n".join(lines)


def env_page(env_id: str, scene: dict) -> str:
    env = gym.make(env_id)
    world = env.unwrapped.world
    rows = [f"| `{section}.{key}` | `{value!r}` |" for section, values in scene.items() for key, value in values.items()]
    env.close()
    return "\n".join([
        f"# {env_id}\n",
        f"`gym.make(\"softenv:{env_id}\")`: the one env class, `SoftSphereEnv`, on this scene. Everything not listed "
        "here is the default of the [settings](../../settings.md); every table of the env (action, observation, "
        "reward, start, episode end, arguments, versions) is on the [environments](../../environments.md) page.\n",
        "| | |", "|---|---|",
        f"| device | `{world.config['device']['kind']}` |",
        f"| action space | `{env.action_space}` |",
        f"| observation space | `Box{env.observation_space.shape}` (`obs_mode=\"vector\"`) |",
        f"| control period | {world.config['dynamics']['dt'] * 1e3:g} ms |",
        f"| episode | `task.horizon` = {world.horizon} steps ({world.horizon * world.config['dynamics']['dt']:g} s), "
        f"task `{world.config['task']['kind']}` |", "",
        "Scene settings this id sets (over the defaults):\n",
        *(["| setting | value |", "|---|---|", *rows] if rows else ["None: this id is the default scene."]), "",
        "```python", "import gymnasium as gym", "", f"env = gym.make(\"softenv:{env_id}\")",
        "obs, info = env.reset(seed=0)", "obs, reward, terminated, truncated, info = env.step(env.action_space.sample())",
        "```", ""])


def leaderboard_page() -> str:
    records = leaderboard.load_results(DOCS.parent / "results" / "leaderboard")
    return "\n".join([
        "# Leaderboard\n",
        "Every result file under `results/leaderboard/`, checked as `softenv leaderboard check` checks it (protocol, "
        "scene, shipped anchors, aggregates recomputed from the per-episode scores) and tabled at each docs build, "
        "best mean first. Normalized score: 0 = no force, 100 = the planning oracle; mean [95 % interval] of every "
        "episode of every run (training seed), the interval a two-level bootstrap over runs and their episodes; "
        "IQM likewise. How to add one: [report a result](../tutorials/report-a-result.md).\n",
        "## Across scenes\n",
        "Each method on every scene of a device, as `rliable` aggregates runs x scenes (each run's mean score on each "
        "scene): IQM, mean and optimality gap (the shortfall from 100) with stratified-bootstrap 95 % intervals, and "
        "the probability that the top method scores above each other one on a scene (`softenv leaderboard aggregate`; "
        "methods without a result on every scene of the device are left out).\n",
        leaderboard.aggregates_table(records),
        "![IQM and optimality gap across each device's scenes, and performance profiles of episode scores]"
        "(../../results/leaderboard_aggregates.png)\n",
        "The figure: `softenv leaderboard aggregate --plot` over the same files, drawn by `scripts/make_leaderboard.py` "
        "(when it was last made: [every result](../results.md)).\n",
        "## By scene\n",
        leaderboard.table(records)])


def generate() -> None:
    out = DOCS / "_generated"
    (out / "envs").mkdir(parents=True, exist_ok=True)
    scenes = {**ENV_SCENES, **HAPTIC_SCENES}
    for env_id, scene in scenes.items():
        (out / "envs" / f"{env_id}.md").write_text(env_page(env_id, scene))
    (out / "env_class.inc").write_text(markdown(SoftSphereEnv.__doc__ or "") + "\n")
    (out / "settings_table.inc").write_text(softenv.describe_config() + "\n")
    (out / "airway_grades.inc").write_text(grade_table() + "\n")
    (out / "api.md").write_text(api_page())
    (out / "leaderboard.md").write_text(leaderboard_page())
    results = DOCS.parent / "results"
    (out / "freshness.inc").write_text(provenance.table(provenance.check(results, DOCS.parent)))


generate()
