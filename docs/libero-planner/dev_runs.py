"""What the scripts that summarise development-layout evaluations share (glsr_choices.py, release_choices.py): read
`tcot eval` episodes from runs/dev/<run>/ into one JSON-lines file kept in docs/, and write a section of
docs/libero-planner.md from it. Imported by those scripts from their own folder."""
from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Callable, Iterable

ROOT = Path(__file__).resolve().parent.parent.parent
SUITES = ("libero_spatial", "libero_object", "libero_goal", "libero_10")
S4 = ",".join(SUITES)
# The four-suite model, named: without --checkpoint a suite that ships its own model (libero_10) loads that one
FOUR_SUITE_MODEL = "--checkpoint tcot_hybrid/checkpoints/libero_panda_default.safetensors"


def gather(runs: Iterable[tuple[str, str]], out: Path, row: Callable[[str, dict], dict | None]) -> None:
    """For each (run directory under runs/dev, the command that makes it): ``row(run, episode)`` of every episode
    (None leaves one out), written to ``out``; a missing run is named with its command."""
    rows = []
    for name, cmd in runs:
        p = ROOT / "runs" / "dev" / name / "episodes.jsonl"
        if not p.is_file():
            print(f"missing {p}: run `{cmd} --workers 2 --out runs/dev/{name}`")
            continue
        for line in p.read_text().splitlines():
            r = row(name, json.loads(line))
            if r is not None:
                rows.append(r)
    out.write_text("\n".join(json.dumps(r) for r in rows) + "\n")
    print(f"{len(rows)} episodes -> {out.relative_to(ROOT)}")


def per_suite(eps: list[dict]) -> list[str]:
    """Successes / episodes of ``eps`` in each of the four suites, as table cells."""
    return [f"{sum(e['success'] for e in eps if e['suite'] == s)}/{sum(e['suite'] == s for e in eps)}" for s in SUITES]


def won_lost(base: dict, eps: list[dict]) -> str:
    """"won / lost" of ``eps`` against ``base`` ((task, seed) -> success) on the layouts both ran."""
    paired = [(base[(e["task"], e["seed"])], e["success"]) for e in eps if (e["task"], e["seed"]) in base]
    return f"{sum(b and not a for a, b in paired)} / {sum(a and not b for a, b in paired)}"


def command_lines(script: str, workers: int, runs: Iterable[tuple[str, str]]) -> list[str]:
    """The docs section's closing list: each (run directory under runs/dev, command) that ``script --gather`` reads."""
    return (["", f"Commands (each with `--workers {workers} --out runs/dev/<run>`; `{script} --gather` reads them):", ""]
            + [f"- `{name}`: `{cmd}`" for name, cmd in runs])


def main(doc: str, gather_runs: Callable[[], None], lines: Callable[[], list[str]], section: str) -> None:
    """``--gather`` runs ``gather_runs`` first; then ``lines()`` replaces ``section`` in docs/libero-planner.md."""
    ap = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--gather", action="store_true", help="read runs/dev/* into the script's JSON file first")
    if ap.parse_args().gather:
        gather_runs()
    from tcot_hybrid.markdown import update_readme_section

    text = "\n".join(lines())
    update_readme_section(ROOT / "docs" / "libero-planner.md", section, text)
    print(text)
