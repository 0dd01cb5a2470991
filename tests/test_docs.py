"""The README's set-up commands are the ones CI and users run."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def readme_commands() -> list[str]:
    text = (ROOT / "README.md").read_text()
    section = text.split("## Set up and run", 1)[1].split("\n## ", 1)[0]
    return re.findall(r"```bash\n(.+?)\n```", section)


def test_readme_shows_exactly_two_setup_commands():
    commands = readme_commands()
    assert len(commands) == 2
    assert all(c.startswith("python3 -m venv .venv && . .venv/bin/activate && pip install -c constraints.txt") for c in commands)
    assert "pytest" in commands[1]


def test_ci_runs_the_readme_test_command():
    ci = (ROOT / ".ci" / "run").read_text()
    assert readme_commands()[1] in ci.splitlines()


def test_the_docs_show_the_readmes_setup_commands_and_every_extra():
    """docs/getting-started.md repeats the README's two commands word for word, and both name every extra."""
    import tomllib

    started = (ROOT / "docs" / "getting-started.md").read_text()
    assert all(command in started.splitlines() for command in readme_commands())
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    readme = (ROOT / "README.md").read_text()
    for extra in extras:
        assert f"`{extra}`" in readme and f"`{extra}`" in started, extra


def test_constraints_pin_the_cpu_torch():
    lines = [line.strip() for line in (ROOT / "constraints.txt").read_text().splitlines()]
    assert "torch==2.13.0" in lines


def test_the_version_is_written_once_and_the_package_is_typed():
    import importlib.metadata
    import tomllib

    import softenv

    project = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert "version" not in project["project"] and project["project"]["dynamic"] == ["version"]
    assert importlib.metadata.version("softenv") == softenv.__version__
    assert (ROOT / "softenv" / "py.typed").exists() and "py.typed" in project["tool"]["setuptools"]["package-data"]["softenv"]
    changelog = (ROOT / "CHANGELOG.md").read_text()
    assert "## [Unreleased]" in changelog and f"## [{softenv.__version__}]" in changelog


def test_the_main_job_and_bench_write_where_git_does_not_look_unless_asked():
    """`softenv compare --quick` and `softenv bench` leave `git status` clean: their default output folder,
    like play's and the README's data folder, is ignored; `--out results` refreshes the committed results."""
    from softenv.cli import build_parser

    parser = build_parser()
    assert parser.parse_args(["compare", "--quick"]).out == "reports"
    assert parser.parse_args(["bench"]).out == "reports"
    assert parser.parse_args(["play"]).out == "play"
    ignored = (ROOT / ".gitignore").read_text().splitlines()
    assert {"reports/", "play/", "data/"} <= set(ignored)
