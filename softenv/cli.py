"""The ``softenv`` command line: ``data``, ``fit``, ``bench`` (and, with the later parts, ``compare``, ``score``).

Each subcommand has ``--help``. Errors in arguments or files end the command with a one-line message
and exit status 2, not a traceback. Ctrl-C (SIGINT) or SIGTERM end it with one line saying what was kept
and how to resume, and exit status 130 or 143; no worker process outlives it.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import secrets
import shutil
import signal
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Callable, NoReturn

import numpy as np

from . import bench, leaderboard
from .airway import GRADES
from .baselines import benchmark
from .baselines import minari_datasets
from .baselines.minari_datasets import DATASET_SCENES, KINDS as DATASET_KINDS
from .baselines.evaluate import EPISODES, SCENES
from .datasets import ForceShapeData, paper_dataset, split_by_contact, split_rows
from .envs import airway_scene
from .evaluation import evaluate_policy
from .parallel import Interrupted, Job, run_jobs, stop_on_signals, usable_cores
from .response import REGRESSORS, MinMaxScaler, make_response
from .shape_model import ShapeModel
from ._artifact import check_out_dir
from ._progress import Progress
from ._validation import check_int, check_real, printable
from .training import play
from .haptics.bridge import LOOPBACK
from .training.hand import haptic_config
from .training.inputs import CONTROLS
from .training.logs import EXAMPLES, MAX_DURATION_S, example_log
from .training.scoring import score_file


def _bounded(kind: type, low: float, high: float | None = None, *, low_open: bool = False) -> Callable[[str], Any]:
    """An argparse type: a number of ``kind`` in ``[low, high]`` (``(low, high]`` with ``low_open``); a bad
    value ends the command before any work with argparse's one line (the option, the value, the range)
    and exit status 2."""
    def parse(text: str) -> Any:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not {'an integer' if kind is int else 'a number'}") from None
        try:
            if kind is int:
                return check_int(value, "value", int(low), None if high is None else int(high))
            return check_real(value, "value", low, high, low_open=low_open)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc).replace("value=", "", 1).replace("value ", "", 1)) from None
    parse.__name__ = kind.__name__             # argparse names the type in its messages
    return parse


def _component_rule(text: str) -> int | float | str:
    """``scree``/``kneedle``/``noise``, a variance fraction such as ``0.99``, or an int."""
    if text in ("scree", "kneedle", "noise"):
        return text
    try:
        return int(text)
    except ValueError:
        pass
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--components {text!r}: use scree, kneedle, noise, a fraction in (0, 1) or an int") from None
    if not 0 < value < 1:
        raise argparse.ArgumentTypeError(f"--components {text!r}: a variance fraction must lie in (0, 1)")
    return value


def cmd_data(args: argparse.Namespace) -> None:
    jobs = [Job(f"{law} {n} points", _paper_data_job,
                (n, args.deformations, args.magnitudes, law, args.noise, args.seed, args.out))
            for law in args.laws for n in args.points]
    try:
        results = run_jobs(jobs, "local", args.jobs, retries=0, echo=lambda line: print(line, file=sys.stderr))
    except Interrupted as stop:
        stop.kept = "the data sets finished so far are cached; run the same command to resume"
        raise
    print(f"{'data set':<34} {'rows':>5} {'coords':>7} {'noise (m)':>10}  file")
    for r in results:
        if not r.ok:
            raise ValueError(f"{r.key}: {r.error}")
        print(r.value)


def _paper_data_job(n: int, deformations: int, magnitudes: int, law: str, noise: float, seed: int,
                    out: str | None) -> str:
    """One paper data set (built or read from the cache; copied to ``out``): its table row."""
    d = paper_dataset(n, deformations, magnitudes, law=law, noise=noise, seed=seed)
    where = "(cache)"
    if out is not None:
        path = Path(out) / f"{d.name}.npz"
        d.save(path)
        where = str(path)
    return f"{d.name:<34} {d.n_samples:>5} {d.shapes.shape[1]:>7} {d.noise_std:>10.2g}  {where}"


def cmd_fit(args: argparse.Namespace) -> None:
    data = (ForceShapeData.load(args.data) if args.data else
            paper_dataset(args.points, args.deformations, args.magnitudes, law=args.law, noise=args.noise, seed=args.seed))
    noise_std = args.noise_std if args.noise_std is not None else (data.noise_std or None)
    model = ShapeModel(args.components, noise_std=noise_std).fit(data.shapes, data.mesh)
    rmse = float(np.sqrt(np.mean((model.reconstruct(data.shapes) - data.shapes) ** 2)))
    print(f"data: {data.name} ({data.n_samples} shapes x {data.shapes.shape[1]} coordinates)")
    print(f"kept k = {model.n_components_} components by rule {model.rule_!r}")
    print("what each rule picks: " + ", ".join(f"{r} {k}" for r, k in model.picks_.items()))
    share = model.explained_variance_.sum() / model.total_variance_
    print(f"explained variance {share:.6f}; reconstruction RMSE {rmse:.3g} m ({rmse * 1e3:.3g} mm)")
    if args.out:
        model.save(args.out)
        print(f"saved {args.out}")
    if args.response:
        fit_response(args, data, model)


def fit_response(args: argparse.Namespace, data: ForceShapeData, shape_model: ShapeModel) -> None:
    """Fit a regressor force -> b on a split of the data and report its test error."""
    split = split_rows(data.n_samples, seed=args.seed) if args.split == "rows" else split_by_contact(data.contact_ids, seed=args.seed)
    b = shape_model.encode(data.shapes)
    model = make_response(args.response, seed=args.seed)
    t0 = time.perf_counter()
    model.fit(data.forces[split.train], b[split.train], validation=(data.forces[split.validation], b[split.validation]),
              shape_model=shape_model)
    fit_s = time.perf_counter() - t0
    pred = model.predict(data.forces[split.test])
    scale = MinMaxScaler.fit(b[split.train])
    mse = float(np.mean((scale.transform(pred) - scale.transform(b[split.test])) ** 2))
    surf = np.sqrt(np.mean((shape_model.decode(pred) - data.shapes[split.test]) ** 2) * 3) * 1e3
    print(f"{args.response} on the {args.split} split: fit {fit_s:.2f} s, test MSE {mse:.3g} (normalised b), "
          f"surface RMSE {surf:.4f} mm over {len(split.test)} test shapes")
    if args.out_response:
        model.save(args.out_response)
        print(f"saved {args.out_response}")


def cmd_bench(args: argparse.Namespace, argv: list[str]) -> None:
    if args.device == "cuda" and not bench.cuda_available():
        raise ValueError("--device cuda: no CUDA device is usable here (a CPU build of torch, or no GPU); "
                         "use --device cpu")
    bench.rerun_single_threaded(argv)
    bench.run(args.quick, Path(args.out), args.only, command=bench.command_line(argv), device=args.device)


def compare_plan(args: argparse.Namespace) -> tuple[benchmark.Plan, str]:
    """The plan of ``softenv compare`` (its profile, narrowed by the options) and its report's stem."""
    profile = "quick" if args.quick else "haptic" if args.haptic else "offline" if args.offline else \
        "graded" if args.graded else "full"
    plan = {"quick": benchmark.quick_plan, "haptic": benchmark.haptic_plan, "offline": benchmark.offline_plan,
            "graded": benchmark.graded_plan, "full": benchmark.full_plan}[profile]()
    if args.scenes:
        plan.scenes = args.scenes
        plan.seeds = {s: plan.seeds.get(s, benchmark.training_seeds(s)) for s in args.scenes}
    if args.policies is not None:
        plan.baselines = args.policies
    if args.agents is not None:
        plan.agents = args.agents
    if args.episodes is not None:
        plan.episodes = args.episodes
    return plan, "benchmark" if profile == "full" else f"benchmark_{profile}"


def cmd_compare(args: argparse.Namespace, argv: list[str]) -> None:
    bench.rerun_single_threaded(argv)
    missing = [name for name in ("stable_baselines3", "torch", "matplotlib") if importlib.util.find_spec(name) is None]
    if missing:
        raise ValueError(f"softenv compare needs the rl and viz extras (pip install 'softenv[all]'): {missing} missing")
    plan, stem = compare_plan(args)
    if any(agent in benchmark.OFFLINE_AGENTS for agent in plan.agents):
        _need_offline("softenv compare's offline agents")
    if args.quick:
        print(f"softenv compare --quick: {' and '.join(plan.scenes)} test targets, {plan.episodes} episodes per policy; "
              f"agents trained now on SoftSphere-v0 for "
              f"{', '.join(f'{a} {n:,}' for a, n in plan.timesteps.items())} env steps (1 seed) -- short budgets, not the "
              "full benchmark")
    benchmark.run(plan, Path(args.out), Path(args.runs), bench.command_line(argv), stem=stem, executor=args.executor,
                  n_jobs=args.jobs if args.jobs is not None else usable_cores(), retries=args.retries)


def _need_offline(what: str) -> None:
    missing = [name for name in ("minari", "jax", "torchrl") if importlib.util.find_spec(name) is None]
    if missing:
        raise ValueError(f"{what} need the offline extra (pip install 'softenv[offline]'): {missing} missing")


def cmd_datasets(args: argparse.Namespace) -> None:
    _need_offline("softenv datasets")
    import minari                                           # the offline extra

    if args.action == "make":
        for scene in args.scenes:
            for kind in args.kinds:
                dataset = minari_datasets.make_dataset(scene, kind, args.episodes, args.runs,
                                                reference_episodes=args.reference_episodes)
                print(printable(f"{dataset.spec.dataset_id}: {dataset.total_episodes} episodes, {dataset.total_steps:,} "
                                f"steps, {minari_datasets.size_bytes(dataset) / 1e6:.1f} MB in {dataset.spec.data_path}"))
        return
    found = [name for name in minari.list_local_datasets() if name.startswith(f"{minari_datasets.NAMESPACE}/")]
    if not found:
        print("no softenv datasets in Minari's local store (softenv datasets make)")
    for name in sorted(found):
        dataset = minari.load_dataset(name)
        meta = dataset.storage.metadata
        print(printable(f"{name}: {dataset.total_episodes} episodes, {dataset.total_steps:,} steps, "
                        f"{minari_datasets.size_bytes(dataset) / 1e6:.1f} MB; {meta.get('algorithm_name')}; reference returns "
                        f"{meta.get('ref_min_score'):.1f} (0) and {meta.get('ref_max_score'):.1f} (1)"))


def cmd_score(args: argparse.Namespace) -> None:
    scene = None                      # the log's own scene (or, for a log that records none, the id's)
    if args.scene is not None or args.law is not None or args.grade is not None:
        scene = {"dynamics": {"kind": args.scene or "quasi_static"}, "tissue": {"law": args.law or "linear"},
                 **(airway_scene(args.grade) if args.grade is not None else {})}
    path = example_log(args.example) if args.example else Path(args.trajectory)
    typed = " ".join(f"--{name} {value}" for name, value in (("scene", args.scene), ("law", args.law),
                                                             ("grade", args.grade)) if value)
    store = open_store(args)                # before the replay: a bad --store or --trainee is refused first
    report = score_file(path, scene, args.out, scene_named=typed or None)
    m = report["metrics"]
    ttt = "never" if m["time_to_target_s"] is None else f"{m['time_to_target_s']:.2f} s"
    parts = ", ".join(f"{k} {report[k]:.2f}" for k in report["weights"])
    print(printable(f"{args.example or args.trajectory} ({report['log']}): score {report['score']:.1f}/100 ({parts}); final error "
          f"{m['final_error_mm']:.3f} mm, time to target {ttt}, peak tongue force {m['peak_force_N']:.1f} N"
          + (f", peak incisor force {m['clinical']['peak_incisor_force_N']:.1f} N" if "clinical" in m else "")))
    if args.out:
        print(printable(f"wrote {args.out}/{path.stem}_score.json, .md, .png"))
    if store is not None:
        with store:
            keep_session(store, path, args.trainee, "score", scene, typed or None)


STORE_MODULES = ("sqlalchemy", "alembic")
DASHBOARD_MODULES = (*STORE_MODULES, "starlette", "starlette_csrf", "uvicorn", "multipart", "jinja2", "matplotlib")


def _need_lab(what: str, modules: tuple[str, ...] = DASHBOARD_MODULES) -> None:
    missing = [m for m in modules if importlib.util.find_spec(m) is None]
    if missing:
        raise ValueError(f"{what} needs the lab extra ({', '.join(missing)} missing): pip install 'softenv[lab]'")


def open_store(args: argparse.Namespace) -> Any:
    """The session store ``--store`` names (the lab extra), or None when no ``--trainee`` asks to keep the session."""
    if args.trainee is None:
        if args.store is not None:
            raise ValueError("--store keeps a session for a trainee: give --trainee ID too")
        return None
    _need_lab("keeping sessions (--trainee)", STORE_MODULES)
    from .skills.store import DEFAULT_STORE, Store, check_trainee        # the lab extra

    check_trainee(args.trainee)
    return Store(args.store or DEFAULT_STORE)


def keep_session(store: Any, path: Path, trainee: str, source: str, scene: dict[str, Any] | None = None,
                 scene_named: str | None = None) -> None:
    kept = store.add(path, trainee, scene=scene, scene_named=scene_named, source=source)
    print(printable(f"kept as session {kept.id} of trainee {trainee} in {store.url}"))


def cmd_serve(args: argparse.Namespace) -> None:
    _need_lab("softenv serve")
    import uvicorn                                                   # the lab extra
    from .skills.cohort import demo_store                            # the lab extra
    from .skills.web import is_loopback, make_app                    # the lab extra
    from .skills.store import Store                                  # the lab extra

    with tempfile.TemporaryDirectory(prefix="softenv-serve-") as folder:
        if args.demo:
            bars: dict[str, Progress] = {}

            def shown(stage: str, done: int, total: int) -> None:
                bar = bars.setdefault(stage, Progress(total, f"demo cohort: {stage}"))
                bar.advance(done - bar.done)
                if done == total:
                    bar.__exit__()                                 # ends the bar's line

            demo = demo_store(progress=shown)
            location: str | Path = Path(folder) / "demo.sqlite"      # a copy: the cached cohort stays as built
            shutil.copyfile(demo, location)
        else:
            location = args.store
        store = Store(location)
        token = args.token or (None if is_loopback(args.host) else secrets.token_urlsafe(18))
        address = f"http://{'[' + args.host + ']' if ':' in args.host else args.host}:{args.port}/"
        print(printable(f"softenv serve: the skills lab at {address}{'?token=' + token if token else ''} "
                        f"(store {store.url}{', the demo cohort' if args.demo else ''}); Ctrl-C stops it"), flush=True)
        try:
            uvicorn.run(make_app(store, token), host=args.host, port=args.port, log_level="warning")
        finally:
            store.close()


def load_policy(spec: str) -> Any:
    """``module:attribute`` (the attribute may be dotted) -> that object; the working directory is importable,
    as it is for ``python -m``."""
    module_name, _, attribute = spec.partition(":")
    if not module_name or not attribute:
        raise ValueError(f"policy {spec!r} must be MODULE:ATTRIBUTE, e.g. my_agent:policy")
    if "" not in sys.path and str(Path.cwd()) not in sys.path:
        sys.path.insert(0, str(Path.cwd()))
    try:
        obj: Any = importlib.import_module(module_name)
    except ImportError as exc:
        raise ValueError(f"policy {spec!r}: module {module_name!r} does not import ({exc})") from None
    for part in attribute.split("."):
        if not hasattr(obj, part):
            raise ValueError(f"policy {spec!r}: {module_name} has no attribute {attribute!r}")
        obj = getattr(obj, part)
    return obj


def cmd_evaluate(args: argparse.Namespace, argv: list[str]) -> None:
    if args.out is not None and args.episodes != EPISODES:
        raise ValueError(f"--out writes a leaderboard result, which takes the protocol's {EPISODES} episodes; "
                         f"--episodes {args.episodes} makes none (drop --out, or --episodes)")
    result = evaluate_policy(load_policy(args.policy), args.scene, args.episodes, name=args.name or args.policy)
    print(printable(str(result)))
    if args.out is not None:
        record = leaderboard.result_record(result, args.kind, "softenv " + bench.command_line(argv))
        print(printable(f"wrote {leaderboard.save_result(record, args.out)} (softenv leaderboard check passes it)"))


def checked_result(path: str) -> tuple[dict[str, Any], dict[str, Any]]:
    """A result file and the aggregates its scores give; a refusal names the file."""
    record = leaderboard.read_result(path)               # names the file itself
    try:
        return record, leaderboard.check_result(record)
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None


def cmd_leaderboard(args: argparse.Namespace) -> None:
    if args.action == "check":
        for path in args.files:
            got = checked_result(path)[1]
            print(printable(f"{path}: ok ({got['mean']:.1f} [{got['ci_low']:.1f}, {got['ci_high']:.1f}])"))
        return
    records = leaderboard.load_results(args.dir) if Path(args.dir).is_dir() else []
    mine = [checked_result(path)[0] for path in args.files]
    if not records and not mine:
        raise ValueError(f"no results to show: {args.dir!r} holds none and no FILE was given")
    if args.action == "aggregate":
        print(leaderboard.aggregates_table(records + mine))
        if args.plot:
            print(printable(f"wrote {leaderboard.aggregates_figure(records + mine, args.plot)}"))
        return
    print(leaderboard.table(records + mine, highlight=mine[0]["method"] if len(mine) == 1 else None))


def cmd_play(args: argparse.Namespace) -> None:
    if importlib.util.find_spec("pygame") is None:
        raise ValueError("softenv play needs pygame (pip install 'softenv[play]')")
    check_out_dir(args.out, "--out")                 # before the session: a refusal after it would lose it
    if args.headless:
        play.headless()
    elif not play.display_available():              # else SDL would run a session nobody sees
        raise ValueError("no display to open a window on (DISPLAY and WAYLAND_DISPLAY are unset): run softenv play "
                         "on a desktop, or pass --headless for a session without a window")
    if args.bridge is not None and args.device != "keys":
        raise ValueError(f"--bridge and --device {args.device} both drive the hand: give one")
    store = open_store(args)                         # before the session, for the same reason
    scene = airway_scene(args.grade) if args.grade is not None else None
    bridge = device = None
    if args.bridge is not None:                      # a device is held to the session's airway's workspace
        host, port = args.bridge
        bridge = play.open_bridge(host, port, haptic_config(scene))
        host, port = bridge.address
        print(f"softenv play: waiting for a device's poses on udp://{host}:{port} (softenv.haptics.bridge)")
    elif args.device != "keys":
        device = play.open_haptic_device(args.device, haptic_config(scene))
    try:
        session = play.run(args.seconds, args.out, scene, bridge=bridge, device=device, screens=not args.headless)
        if store is not None:
            keep_session(store, session.log_path, args.trainee, "play")
    finally:
        for opened in (bridge, device, store):
            if opened is not None:
                opened.close()


def _bridge_address(text: str) -> tuple[str, int]:
    """``PORT`` or ``HOST:PORT`` (port 0-65535; 0 picks a free one) -> (host, port); host 127.0.0.1 unless given."""
    host, _, port = text.rpartition(":")
    if not port.isdigit() or int(port) > 65535:
        raise argparse.ArgumentTypeError(f"{text!r} must be PORT or HOST:PORT with a port in 0-65535")
    return host or LOOPBACK, int(port)


class OneLineParser(argparse.ArgumentParser):
    """argparse, with a refused option reported in one line (no usage block): ``softenv <cmd>: error: ...``."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, printable(f"{self.prog}: error: {message}\n"))


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(prog="softenv", description="Soft-tissue deformation benchmark: data, models, benchmarks.",
                           epilog="Exit status: 0 done, 2 bad input (one line says which), 130 or 143 stopped by Ctrl-C "
                                  "or SIGTERM (one line says what was kept and how to resume).")
    sub = parser.add_subparsers(dest="command", required=True)

    def paper_args(p: argparse.ArgumentParser, many: bool) -> None:
        if many:
            p.add_argument("--points", type=_bounded(int, 9, 40_000), nargs="+", default=[441, 961],
                           help="surface points per data set (square numbers, 9-40000; default: 441 961)")
            p.add_argument("--laws", nargs="+", default=["linear", "stiffening"], choices=["linear", "stiffening"],
                           help="tissue laws, one data set each: linear, stiffening (default: both)")
        else:
            p.add_argument("--points", type=_bounded(int, 9, 40_000), default=961,
                           help="surface points (441 or 961 in the paper; 9-40000)")
            p.add_argument("--law", default="linear", choices=["linear", "stiffening"])
        p.add_argument("--deformations", type=_bounded(int, 1, 1000), default=10,
                       help="contact points (paper: up to 10; 1-1000)")
        p.add_argument("--magnitudes", type=_bounded(int, 2, 1000), default=11,
                       help="force magnitudes per contact point (paper: 11; 2-1000)")
        p.add_argument("--noise", type=_bounded(float, 0.0, 1.0), default=1e-5,
                       help="white-noise std as a fraction of the radius (0-1)")
        p.add_argument("--seed", type=_bounded(int, 0, 2**32 - 1), default=0, help="random seed of the noise (default 0)")

    p = sub.add_parser("data", help="generate the paper's data sets (cached; --out writes copies)")
    paper_args(p, many=True)
    p.add_argument("--out", help="directory for .npz copies")
    p.add_argument("--jobs", type=_bounded(int, 1, 4096), default=1,
                   help="local worker processes (default 1: in this process)")

    p = sub.add_parser("fit", help="fit a PCA shape model and report k, the rules' picks and the error")
    paper_args(p, many=False)
    p.add_argument("--data", help="a data set .npz written by 'softenv data --out' (instead of the paper set)")
    p.add_argument("--components", type=_component_rule, default="scree",
                   help="scree | kneedle | noise | variance fraction (0.99) | int")
    p.add_argument("--noise-std", type=_bounded(float, 0.0, None, low_open=True),
                   help="noise std in metres for the noise rule (> 0; default: the data's)")
    p.add_argument("--out", help="write the shape model to this .npz")
    p.add_argument("--response", choices=list(REGRESSORS), help="also fit this force -> b regressor and report its test error")
    p.add_argument("--split", choices=["rows", "contacts"], default="rows",
                   help="random rows (the paper's) or held-out contact points")
    p.add_argument("--out-response", help="write the regressor to this .npz")

    p = sub.add_parser("bench", help="speed and memory benchmarks against CartPole-v1 (writes perf.md/.json)")
    p.add_argument("--quick", action="store_true", help="smaller sizes; writes perf_quick.*")
    p.add_argument("--out", default="reports", help="output directory (default: reports, which git ignores; "
                                                    "--out results refreshes the committed results)")
    p.add_argument("--only", nargs="+", choices=list(bench.SECTIONS), metavar="SECTION",
                   help=f"run only these sections: {', '.join(bench.SECTIONS)} (default: all but the GPU sections "
                        f"{' and '.join(bench.GPU_SECTIONS)}, which run with --device cuda)")
    p.add_argument("--device", choices=["cpu", "cuda"], default="cpu",
                   help="cuda: the torch twins on the GPU alone (the GPU sections, or those named by --only), written to "
                        "perf-gpu.md (needs a CUDA device)")

    p = sub.add_parser("compare", help="baselines and RL agents on the benchmark scenes (the main job)")
    profile = p.add_mutually_exclusive_group()
    profile.add_argument("--quick", action="store_true",
                         help="SoftSphere-v0 and SoftSphereHaptic-v0, short agent training (under 3 minutes on 2 cores)")
    profile.add_argument("--haptic", action="store_true",
                         help="the two laryngoscope scenes, every baseline, the four agents at their converged budgets "
                              "over 10 seeds (report benchmark_haptic.*; on 2 cores most of a day from an empty --runs, "
                              "minutes with its agents trained)")
    profile.add_argument("--graded", action="store_true",
                         help="the difficult airways: SoftSphereAirway-v0 at every grade, its baselines and oracle "
                              "per grade, the agents trained on grades 1 and 2 and evaluated on every grade "
                              "(report benchmark_graded.*, with score against grade in benchmark_graded_grades.png)")
    profile.add_argument("--offline", action="store_true",
                         help="behaviour cloning and TD3+BC on each Minari dataset of SoftSphereHaptic-v0 (made first "
                              "where missing), 3 seeds each (report benchmark_offline.*; needs softenv[offline])")
    p.add_argument("--scenes", nargs="+", choices=list(benchmark.SCENES), metavar="SCENE",
                   help=f"benchmark scenes: {', '.join(benchmark.SCENES)} (default: all in full mode)")
    p.add_argument("--policies", nargs="*", choices=list(benchmark.POLICIES), metavar="POLICY",
                   help=f"baseline policies: {', '.join(benchmark.BASELINES)} (default: all; none: no baselines); "
                        f"{benchmark.GRADIENT_PLANNER!r} (Adam on each test episode's actions through the "
                        "differentiable torch twin: most of an hour a laryngoscope scene) in the full profile, on "
                        "request in the others")
    p.add_argument("--agents", nargs="*", choices=list(benchmark.AGENTS), metavar="AGENT",
                   help="agents: ppo sac td3 sac-her (SB3), ppo-torch (baselines/ppo_torch.py, on the GPU when "
                   "present; every scene), shac (first-order, through the differentiable torch twin), bc-KIND and "
                   "td3bc-KIND (offline, on a Minari dataset of KIND: expert oracle mixed novice random ppo) "
                   "(default: quick, haptic and graded: the four SB3 agents; full: those and shac)")
    p.add_argument("--episodes", type=_bounded(int, 1, 100_000),
                   help="test episodes per policy and scene (1-100000; default 100)")
    p.add_argument("--out", default="reports", help="report directory (default: reports, which git ignores; "
                                                    "--out results refreshes the committed results)")
    p.add_argument("--runs", default="runs", help="run directory: finished jobs and trained agents, read back by "
                                                  "the next run of the same plan, so a stopped run resumes (default: runs)")
    p.add_argument("--jobs", type=_bounded(int, 1, 4096), default=None,
                   help="worker processes (local) or CPUs of a new local Ray instance (default: every usable core; "
                        "1: in this process); results do not depend on it")
    p.add_argument("--executor", choices=["local", "ray"], default="local",
                   help="local processes, or Ray tasks (RAY_ADDRESS names the cluster; softenv[ray])")
    p.add_argument("--retries", type=_bounded(int, 0, 100), default=1,
                   help="re-runs of a failed job before it is reported (0-100; default 1)")

    p = sub.add_parser("datasets", help="Minari datasets of the laryngoscope scenes: make them, or list those made")
    actions = p.add_subparsers(dest="action", required=True)
    q = actions.add_parser("make", help="record datasets into Minari's local store ($MINARI_DATASETS_PATH, else "
                                        "~/.minari/datasets), replacing any of the same id")
    q.add_argument("--scenes", nargs="+", choices=list(DATASET_SCENES), default=["SoftSphereHaptic-v0"], metavar="SCENE",
                   help=f"laryngoscope scenes: {', '.join(DATASET_SCENES)} (default: SoftSphereHaptic-v0)")
    q.add_argument("--kinds", nargs="+", choices=list(DATASET_KINDS), default=list(DATASET_KINDS), metavar="KIND",
                   help=f"demonstrators: {', '.join(DATASET_KINDS)} (default: all)")
    q.add_argument("--episodes", type=_bounded(int, 1, 100_000), default=100, help="episodes per dataset (default 100)")
    q.add_argument("--reference-episodes", type=_bounded(int, 1, EPISODES), default=EPISODES,
                   help=f"test episodes the reference returns average (default: the protocol's {EPISODES})")
    q.add_argument("--runs", default="runs", help="where the ppo dataset's agent is trained, or read back (default: runs)")
    actions.add_parser("list", help="the softenv datasets in Minari's local store, with their sizes")

    p = sub.add_parser("play", help="drive the laryngoscope yourself (keyboard, mouse, gamepad); scored at the end",
                       formatter_class=argparse.RawDescriptionHelpFormatter,
                       description="A start screen states the task; the window shows the tongue against the target, "
                                   "the laryngoscope and the forces; an end screen gives the score, each part against "
                                   "the expert's, and what to improve first.",
                       epilog="controls:\n" + "\n".join(f"  {key:<14}{what}" for key, what in CONTROLS))
    p.add_argument("--seconds", type=_bounded(float, 0.0, MAX_DURATION_S, low_open=True), default=10.0,
                   help=f"session length in s (0-{MAX_DURATION_S:g}, the longest log that can be scored; default 10)")
    p.add_argument("--out", default="play", help="where the device log and its score report go (default: play)")
    grade_arg(p, "the session's airway")
    p.add_argument("--headless", action="store_true",
                   help="no window (SDL's dummy driver) and no start or end screen: the session starts at once and "
                        "ends with its score (a bridge-driven or smoke run)")
    p.add_argument("--device", choices=["keys", "touch", "forcedimension"], default="keys",
                   help="what drives the hand: keys, mouse and gamepad (default); a 3D Systems Touch (the touch "
                        "extra and OpenHaptics) or a Force Dimension arm (the forcedimension extra and its SDK), "
                        "both untested without the hardware")
    p.add_argument("--bridge", type=_bridge_address, metavar="[HOST:]PORT",
                   help="a haptic device drives the hand over UDP (softenv.haptics.bridge: poses in, force out); "
                        "listens on 127.0.0.1:PORT unless HOST is given (another address lets other machines in)")
    store_args(p)

    p = sub.add_parser("evaluate", help="score a policy of yours under the benchmark's protocol (normalized score with "
                                        "95 %% intervals; --out writes a leaderboard result)")
    p.add_argument("policy", help="MODULE:ATTRIBUTE naming a batched callable obs -> actions, a stable-baselines3 "
                                  "model, or an object with predict(obs) and reset() (a list: one per training seed)")
    p.add_argument("--scene", choices=list(SCENES), default="SoftSphere-v0", metavar="SCENE",
                   help=f"a benchmark scene (default SoftSphere-v0): {', '.join(SCENES)}")
    p.add_argument("--episodes", type=_bounded(int, 1, 100_000), default=EPISODES,
                   help=f"test episodes (default and for --out: the protocol's {EPISODES})")
    p.add_argument("--name", help="the method's name in the result (default: the policy's MODULE:ATTRIBUTE)")
    p.add_argument("--kind", choices=list(leaderboard.KINDS), default="submission", help="the result's kind")
    p.add_argument("--out", help="write the result file here (JSON; checked as softenv leaderboard check does)")

    p = sub.add_parser("leaderboard", help="check result files, or show where they stand")
    actions = p.add_subparsers(dest="action", required=True)
    q = actions.add_parser("check", help="validate result files: schema, protocol, scene, anchors, aggregates")
    q.add_argument("files", nargs="+", metavar="FILE")
    for action, text in (("show", "the leaderboard of a folder of results, with FILEs among them"),
                         ("aggregate", "each method across the scenes of a device (IQM, mean, optimality gap, "
                                       "probability of improvement; stratified bootstrap)")):
        q = actions.add_parser(action, help=text)
        q.add_argument("files", nargs="*", metavar="FILE")
        q.add_argument("--dir", default="results/leaderboard", help="the folder of results (default: results/leaderboard)")
        if action == "aggregate":
            q.add_argument("--plot", help="also draw the aggregates and performance profiles into this PNG")

    p = sub.add_parser("score", help="score a recorded trainee log (CSV or NPZ) against the expert")
    log = p.add_mutually_exclusive_group(required=True)
    log.add_argument("trajectory", nargs="?", help="a device log (time_s, hand_x_m, hand_z_m, hand_pitch_rad, "
                     "hand_y_m) or a force-command log (time_s, insertion_deg, lateral_deg, normal_N, sideways_N)")
    log.add_argument("--example", choices=EXAMPLES, metavar="NAME",
                     help=f"a log shipped with softenv instead of a file: {', '.join(EXAMPLES)}")
    p.add_argument("--scene", choices=["quasi_static", "viscoelastic"],
                   help="tissue dynamics of the replay: quasi_static or viscoelastic. A log records its scene and "
                        "is replayed on it (a contradicting --scene or --law is refused); for an old log that "
                        "records none: quasi_static unless given")
    p.add_argument("--law", choices=["linear", "stiffening"],
                   help="tissue law of the replay: linear or stiffening (as --scene: the log's own if it records "
                        "one; else linear unless given)")
    grade_arg(p, "the replay's airway (as --scene: the log's own if it records one)")
    p.add_argument("--out", help="write <name>_score.json, .md and .png here")
    store_args(p)

    p = sub.add_parser("serve", help="the skills lab's dashboard in the browser: the cohort, trainees, sessions, "
                       "uploads, pass marks (the lab extra)")
    p.add_argument("--store", default="skills.sqlite", help="the session store: a SQLite file or a database URL "
                   "(postgresql+psycopg://user:password@host/db); default skills.sqlite")
    p.add_argument("--demo", action="store_true", help="serve a demo cohort (12 synthetic trainees, 10 sessions each; "
                   "built into the cache on first use, about a minute) instead of --store")
    p.add_argument("--host", default="127.0.0.1", help="the address to listen on (default 127.0.0.1, this machine "
                   "only; any other address requires the token)")
    p.add_argument("--port", type=_bounded(int, 1, 65535), default=8000, help="the port (default 8000)")
    p.add_argument("--token", help="the token every request must carry (default: none on a loopback address, a "
                   "random one printed at start on any other)")
    return parser


def grade_arg(p: argparse.ArgumentParser, what: str) -> None:
    """--grade: an airway grade of SoftSphereAirway-v0 (softenv.airway)."""
    p.add_argument("--grade", type=int, choices=list(GRADES), help=f"{what}: a difficult-airway grade, "
                   + ", ".join(f"{g} {name}" for g, (name, *_) in GRADES.items())
                   + " (SoftSphereAirway-v0's device range; default: SoftSphereHaptic-v0's normal airway)")


def store_args(p: argparse.ArgumentParser) -> None:
    """--trainee and --store: keep the scored session in a skills-lab store (the lab extra)."""
    p.add_argument("--trainee", help="keep the scored session for this trainee (a pseudonymous id such as T-017) in "
                   "the session store")
    p.add_argument("--store", help="the session store --trainee keeps it in: a SQLite file or a database URL "
                   "(default skills.sqlite)")


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        args = build_parser().parse_args(argv)      # every option checked here, before any work
    except SystemExit as exc:                         # argparse's one line (or --help) has been printed
        return int(exc.code or 0)
    try:
        with stop_on_signals():               # SIGTERM stops as Ctrl-C does: one line, no traceback
            return _dispatch(args, argv)
    except BrokenPipeError:                   # the reader stopped early (| head): what it read was what it wanted
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())      # no second error at exit's flush
        return 0
    except (ValueError, OSError) as exc:        # bad arguments, files, or a file system that refuses
        print(printable(f"softenv {args.command}: error: {exc}"), file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:            # Interrupted, or a Ctrl-C outside a fan-out
        stop = exc if isinstance(exc, Interrupted) else Interrupted(signal.SIGINT)
        print(printable(f"softenv {args.command}: stopped by {signal.Signals(stop.signum).name}"
                        + (f"; {stop.kept}" if stop.kept else "")), file=sys.stderr)
        return stop.exit_status


def _dispatch(args: argparse.Namespace, argv: list[str]) -> int:
    if args.command == "data":
        cmd_data(args)
    elif args.command == "fit":
        cmd_fit(args)
    elif args.command == "bench":
        cmd_bench(args, argv)
    elif args.command == "compare":
        cmd_compare(args, argv)
    elif args.command == "evaluate":
        cmd_evaluate(args, argv)
    elif args.command == "datasets":
        cmd_datasets(args)
    elif args.command == "leaderboard":
        cmd_leaderboard(args)
    elif args.command == "score":
        cmd_score(args)
    elif args.command == "play":
        cmd_play(args)
    elif args.command == "serve":
        cmd_serve(args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
