"""Numbers in prose come from the results they cite: in every paragraph or list item of the README and of
every page under docs/ that names a file under ``results/`` (and in a table right below such a paragraph,
which it introduces), each decimal number (and each number with a thousands separator; a table's
"target" column, a goal the results are held to, is not a claim) must be one of the cited files' numbers,
rounded as the prose writes it (``70.6 M`` or ``70.6 million`` for 70,6xx,xxx; ``7.9e-5`` for 7.93e-05),
and each estimate with its interval (``98.7 [98.4, 99.0]``) must be one the files print whole, so a mean
cannot be paired with another row's interval.
A number in code (between backticks) or in a block of code is not prose."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
# Every document is checked: a page that cannot be yet is listed here with the reason.
NOT_YET: set[str] = set()
CHECKED = ["README.md"] + sorted(p.relative_to(ROOT).as_posix() for p in (ROOT / "docs").glob("**/*.md")
                                 if p.relative_to(ROOT).as_posix() not in NOT_YET
                                 and not {"_generated", "_build"} & set(p.parts))
_CITE = re.compile(r"results/[A-Za-z0-9_./-]*[A-Za-z0-9_-]")
_CLAIM = re.compile(r"(?<![\w.])(\d{1,3}(?:,\d{3})+(?:\.\d+)?|\d+\.\d+(?:e-?\d+)?|\d+e-?\d+)(?:\s?(k|M|million)\b)?")
_SOURCE = re.compile(r"(?<![\w.])(\d{1,3}(?:,\d{3})+(?:\.\d+)?|\d+(?:\.\d+)?(?:e[-+]?\d+)?)")
_TRIPLE = re.compile(r"(-?\d+(?:\.\d+)?) \[(-?\d+(?:\.\d+)?), (-?\d+(?:\.\d+)?)\]")
_TEXT = {".md", ".json", ".csv", ".txt"}


def blocks(text: str) -> list[str]:
    """Paragraphs, list items, headings and tables (a table's rows together), outside fenced code."""
    out: list[str] = []
    current: list[str] = []
    fenced = False
    for line in text.splitlines():
        in_table = bool(current) and current[0].startswith("|") and line.startswith("|")
        starts = not line.strip() or re.match(r"^\s{0,2}[-*] ", line) or line.startswith(("#", "|", "```"))
        if starts and current and not in_table:
            out.append("\n".join(current))
            current = []
        if line.startswith("```"):
            fenced = not fenced
        elif not fenced and line.strip():
            current.append(line)
    return out + (["\n".join(current)] if current else [])


def without_targets(table: str) -> str:
    """A table's rows less the cells under a "target" header."""
    rows = [line.strip().strip("|").split("|") for line in table.splitlines()]
    keep = [i for i, cell in enumerate(rows[0]) if cell.strip().lower() != "target"]
    return "\n".join("| " + " | ".join(row[i].strip() for i in keep if i < len(row)) + " |" for row in rows)


def cited_files(block: str) -> list[Path]:
    files = []
    for cite in set(_CITE.findall(block)):
        path = ROOT / cite
        files += sorted(f for f in path.rglob("*") if f.suffix in _TEXT) if path.is_dir() else \
            ([path] if path.suffix in _TEXT and path.exists() else [])
    return files


def numbers(text: str) -> set[float]:
    return {float(n.replace(",", "")) for n in _SOURCE.findall(text)}


def matches(claim: str, suffix: str, source: set[float]) -> bool:
    """``claim`` is some source number as the prose rounds it: to its decimals, or (``7.9e-5``) to its
    significant digits, after the ``k``/``M`` it carries."""
    scale = {"k": 1e3, "M": 1e6, "million": 1e6}.get(suffix, 1.0)
    mantissa, _, exponent = claim.replace(",", "").partition("e")
    decimals = len(mantissa.partition(".")[2])
    if exponent:
        return any(v > 0 and f"{v:.{decimals}e}" == f"{float(claim):.{decimals}e}" for v in source)
    value = float(mantissa)
    return any(abs(round(v / scale, decimals) - value) < 1e-9 for v in source)


def mismatches(document: str) -> list[str]:
    found = []
    introduced: list[Path] = []                  # what the paragraph above a table cites
    for block in blocks((ROOT / document).read_text(encoding="utf-8")):
        files = cited_files(block)
        if block.startswith("|"):
            files, block = files + introduced, without_targets(block)
        else:
            introduced = [] if block.startswith("#") else files
        if not files:
            continue
        text = "\n".join(f.read_text(encoding="utf-8", errors="replace") for f in files)
        source = numbers(text)
        prose = " ".join(re.sub(r"\]\([^)]*\)", "]", re.sub(r"`[^`]*`", "", block)).split())
        printed = set(_TRIPLE.findall(text))
        found += [f"{m} [{lo}, {hi}] is printed by none of {[f.relative_to(ROOT).as_posix() for f in files]}"
                  for m, lo, hi in _TRIPLE.findall(prose) if (m, lo, hi) not in printed]
        found += [f"{claim}{suffix} is in none of {[f.relative_to(ROOT).as_posix() for f in files]}: "
                  f"{prose[:160]}"
                  for claim, suffix in _CLAIM.findall(prose) if not matches(claim, suffix, source)]
    return found


@pytest.mark.parametrize("document", CHECKED)
def test_prose_numbers_come_from_the_results_they_cite(document: str) -> None:
    assert mismatches(document) == []


def test_the_check_finds_a_number_its_results_do_not_hold() -> None:
    source = numbers("| ppo | 98.64 [97.95, 99.12] | 70,612,345 env-steps/s | 7.93e-05 |")
    assert matches("98.6", "", source) and matches("70.6", "M", source) and matches("7.9e-5", "", source)
    assert matches("70,612,345", "", source)
    assert not matches("98.7", "", source) and not matches("70.7", "M", source)
    assert not matches("8.0e-5", "", source)
    assert _TRIPLE.findall("PPO 98.7 [98.4, 99.0] above") == [("98.7", "98.4", "99.0")]
    assert blocks("a 1.5\nb\n\n- c 2.5\n- d\n```\n3.5\n```\ne") == ["a 1.5\nb", "- c 2.5", "- d", "e"]
    assert blocks("a\n| x |\n|---|\n| 1.5 |\n\nb") == ["a", "| x |\n|---|\n| 1.5 |", "b"]
    assert without_targets("| what | target |\n|---|---|\n| 1.5 | >= 2.5 |") == "| what |\n| --- |\n| 1.5 |"
