"""What the scripts that summarise development-layout evaluations share (glsr_choices.py, release_choices.py): read
`tcot eval` episodes from runs/dev/<run>/ into one JSON-lines file kept in docs/, and write a section of
docs/libero-planner.md from it. Imported by those scripts from their own folder."""
from __future__ import annotations

import argparse
import json
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable

ROOT = Path(__file__).resolve().parent.parent.parent
SUITES = ("libero_spatial", "libero_object", "libero_goal", "libero_10")
S4 = ",".join(SUITES)
# The four-suite model, named: without --checkpoint a suite that ships its own model (libero_10) loads that one
FOUR_SUITE_MODEL = "--checkpoint tcot_hybrid/checkpoints/libero_panda_default.safetensors"


def episode_config(task: str, seed: int, planner: str, mode: str = "global", checkpoint: str | None = None):
    """The run configuration of one development episode as `tcot run --robot auto --init sampled` makes it (the
    diagnostics book_grasp.py, first_plan.py and goal_trace.py run single episodes in their own processes); ``checkpoint``
    as `--checkpoint` (None: the task's shipped model)."""
    from tcot_hybrid.planners import check_checkpoint_used
    from tcot_hybrid.run_config import RunConfig
    from tcot_hybrid.supervision import SupervisorConfig

    check_checkpoint_used(checkpoint, [planner])  # as `tcot run`: the oracle would ignore it
    return RunConfig(task=task, seed=seed, robot="auto", init="sampled", planner=planner,
                     supervisor=SupervisorConfig(mode=mode), checkpoint=checkpoint)


def gather(runs: Iterable[tuple[str, str]], out: Path, row: Callable[[str, dict], dict | None]) -> None:
    """For each (run directory under runs/dev, the command that makes it): ``row(run, episode)`` of every episode
    (None leaves one out), written to ``out``; a missing run keeps the rows ``out`` already holds for it (runs/ does
    not travel between machines, the gathered file does), or is named with its command. A row whose ``run`` is not
    its directory (a setting shared by several runs) also keeps the directory, as ``dir``, so it is found again."""
    before: dict = defaultdict(list)
    if out.is_file():
        for line in out.read_text().splitlines():
            if line.strip():
                r = json.loads(line)
                before[r.get("dir", r.get("run"))].append(r)
    rows = []
    for name, cmd in runs:
        p = ROOT / "runs" / "dev" / name / "episodes.jsonl"
        if not p.is_file():
            if before.get(name):
                print(f"{name}: runs/dev/{name} is not on this machine; keeping its {len(before[name])} gathered rows")
                rows += before[name]
            else:
                print(f"missing {p}: run `{cmd} --workers 2 --out runs/dev/{name}`")
            continue
        for line in p.read_text().splitlines():
            r = row(name, json.loads(line))
            if r is not None:
                rows.append(r if r.get("run") == name else {**r, "dir": name})
    out.write_text("\n".join(json.dumps(r) for r in rows) + "\n")
    print(f"{len(rows)} episodes -> {out.relative_to(ROOT)}")


def per_suite(eps: list[dict]) -> list[str]:
    """Successes / episodes of ``eps`` in each of the four suites, as table cells ("-" for a suite without any)."""
    return [f"{sum(e['success'] for e in eps if e['suite'] == s)}/{n}" if (n := sum(e['suite'] == s for e in eps)) else "-"
            for s in SUITES]


def frac(eps: list[dict]) -> str:
    """Successes / episodes of ``eps`` ("-" for none)."""
    return f"{sum(e['success'] for e in eps)}/{len(eps)}" if eps else "-"


def won_lost(base: dict, eps: list[dict]) -> str:
    """"won / lost" of ``eps`` against ``base`` ((task, seed) -> success) on the layouts both ran."""
    paired = [(base[(e["task"], e["seed"])], e["success"]) for e in eps if (e["task"], e["seed"]) in base]
    return f"{sum(b and not a for a, b in paired)} / {sum(a and not b for a, b in paired)}"


def won_lost_keyed(base: dict, eps: dict) -> str:
    """:func:`won_lost` of ``eps`` given as (task, seed) -> success, like ``base``."""
    return won_lost(base, [{"task": t, "seed": s, "success": ok} for (t, s), ok in eps.items()])


def per_task_table(columns: list[tuple[str, dict]]) -> list[str]:
    """A markdown table of successes / episodes per task, one column per (header, (task, seed) -> success); "-"
    where a column ran none of a task's layouts."""
    out = ["| task | " + " | ".join(head for head, _ in columns) + " |", "|" + "---|" * (len(columns) + 1)]
    for task in sorted({t for _, eps in columns for t, _ in eps}):
        cells = []
        for _, eps in columns:
            got = [ok for (t, _), ok in eps.items() if t == task]
            cells.append(f"{sum(got)}/{len(got)}" if got else "-")
        out.append(f"| {task.split(':', 1)[1]} | " + " | ".join(cells) + " |")
    return out


def against_first(base: dict, key, eps: list[dict]) -> str:
    """Won / lost of ``eps`` against the first rows seen under ``key``; those first rows become its baseline (kept
    in ``base``) and get "-"."""
    if key not in base:
        base[key] = {(e["task"], e["seed"]): e["success"] for e in eps}
        return "-"
    return won_lost(base[key], eps)


SUITE_KEEP = ("task", "suite", "mode", "seed", "success", "stopped_by", "premature_stop")


def gather_suite(runs: Iterable[tuple[str, str]], out: Path, suite: str) -> None:
    """:func:`gather` of the unperturbed episodes of one suite, for :func:`model_table`."""
    gather(runs, out, lambda name, e: ({"run": name, **{k: e.get(k) for k in SUITE_KEEP}}
                                       if e["perturb"] == "none" and e["suite"] == suite else None))


def _retreat_column(ck: str, how: str, mode: str) -> str:
    return f"{ck.split(' (')[0]}, {'retreat' if how.startswith('retreat') else 'no retreat'}, {mode}"


def model_table(rows: list[dict], table_rows, suite: str, first_seed: int = 20000,
                column: Callable[[str, str, str], str] = _retreat_column) -> list[str]:
    """A suite's development-layout table: one line per (checkpoint, executor, mode, runs whose episodes of ``suite``
    make the row), each mode's first row the baseline its won / lost counts against; then successes per task for
    the rows that ran all six layouts from ``first_seed``, headed ``column(checkpoint, executor, mode)``. ``rows``:
    gathered episodes, each with its ``run``."""
    out = [f"{suite} on sampled development layouts {first_seed}-{first_seed + 5} (6 per task; a row that ran fewer "
           "says which; won / "
           "lost against the first row of its mode on the layouts both ran):", "",
           "| checkpoint | executor | mode | layouts | successes | won / lost |", "|---|---|---|---|---|---|"]
    base: dict = {}
    per_task: dict = defaultdict(dict)
    for ck, how, mode, runs in table_rows:
        eps = {(r["task"], r["seed"]): r for r in rows if r["run"] in runs and r["mode"] == mode and r["suite"] == suite}
        if not eps:
            continue
        seeds = sorted({s for _, s in eps})
        wl = against_first(base, mode, list(eps.values()))
        k = sum(e["success"] for e in eps.values())
        out.append(f"| {ck} | {how} | {mode} | {seeds[0]}-{seeds[-1]} ({len(eps)}) | **{k}/{len(eps)}** | {wl} |")
        if len(seeds) == 6:
            name = column(ck, how, mode)
            for (task, _), e in eps.items():
                got = per_task[task].setdefault(name, [0, 0])
                got[0] += bool(e["success"])
                got[1] += 1
    cols = list(dict.fromkeys(c for t in per_task.values() for c in t))
    out += ["", "Per task (rows over all six layouts):", "", "| task | " + " | ".join(cols) + " |",
            "|" + "---|" * (len(cols) + 1)]
    for task in sorted(per_task):
        out.append(f"| {task.split(':', 1)[1]} | " + " | ".join(
            "%d/%d" % tuple(per_task[task][c]) if c in per_task[task] else "-" for c in cols) + " |")
    return out


def per_mode(runs) -> tuple:
    """(run, mode, checkpoint label, command) for each (run, checkpoint label, command) in ``runs`` and each of its
    modes, global-only first: the rows :func:`checkpoint_table` takes."""
    return tuple((run, mode, label, cmd) for run, label, cmd in runs for mode in ("global", "glsr"))


def checkpoint_table(rows: list[dict], runs, head: str = "checkpoint") -> list[str]:
    """Successes / episodes per suite of each (run, mode, label, command) in ``runs``, read from gathered ``rows``
    (each with its ``run``), the labels' column headed ``head``; each mode's first row is the baseline its won / lost
    counts against."""
    by: dict = defaultdict(list)
    for r in rows:
        by[(r["run"], r["mode"])].append(r)
    out = [f"| {head} | mode | " + " | ".join(SUITES) + " | all four | won / lost |", "|" + "---|" * (len(SUITES) + 4)]
    base: dict = {}
    for name, mode, ck, _ in runs:
        eps = by.get((name, mode))
        if not eps:
            continue
        wl = against_first(base, mode, eps)
        out.append(f"| {ck} | {mode} | " + " | ".join(per_suite(eps))
                   + f" | **{sum(e['success'] for e in eps)}/{len(eps)}** | {wl} |")
    return out


def changed_tasks(rows: list[dict], mode: str, base: str, run: str, per_task: int, base_label: str) -> str:
    """Tasks whose successes in ``mode`` differ between run ``base`` (called ``base_label``) and run ``run``, each of
    ``per_task`` layouts, from gathered ``rows`` (each with its ``run``)."""
    count: dict = defaultdict(lambda: defaultdict(int))
    for r in rows:
        if r["mode"] == mode:
            count[r["task"].split(":", 1)[1]][r["run"]] += r["success"]
    diff = [f"{t} {c[base]} -> {c[run]}" for t, c in sorted(count.items()) if c[base] != c[run]]
    return (f"Tasks whose count differs in {mode} (of {per_task}, {base_label} -> {run}): " + ("; ".join(diff) or "none")
            + ".")


@dataclass(frozen=True)
class SuiteModelComparison:
    """A suite's own model judged against another on sampled development layouts, global-only and GLSR: each of
    ``models`` ((short name, label, `--checkpoint` flag); the first is the baseline) on ``layouts`` layouts a task
    from each first seed of ``seed_ranges``, into runs/dev/<prefix>_<short>[b...]. ``modes``: GLSR alone for models
    whose plans are bit-identical (a detector trained alone), where global-only cannot differ. ``tasks``: those of
    the suite's tasks alone (all of them when empty)."""

    prefix: str
    suite: str
    seed_ranges: tuple[int, ...]
    layouts: int
    models: tuple[tuple[str, str, str], ...]
    modes: tuple[str, ...] = ("global", "glsr")
    tasks: tuple[str, ...] = ()
    layouts_kind: str = "development"  # what the layouts are for (docs/seeds.md), as the docs section names them

    @property
    def runs(self) -> tuple[tuple[str, str, str], ...]:
        """(run directory under runs/dev, model label, command) of every run."""
        which = f"--tasks {','.join(self.tasks)}" if self.tasks else f"--suite {self.suite}"
        cmd = (f"tcot eval {which} --planners learned --init sampled --episodes {self.layouts} "
               f"--modes {','.join(self.modes)}")
        return tuple((f"{self.prefix}_{short}{'b' * k}", label, f"{cmd} --seed-start {first} {flag}".rstrip())
                     for short, label, flag in self.models for k, first in enumerate(self.seed_ranges))

    def lines(self, out: Path, script: str) -> list[str]:
        """The docs section of the episodes gathered in ``out``: successes per run and in all, won / lost against
        the first model in the same mode on the same layouts, then per task."""
        runs, layouts = self.runs, self.layouts
        by: dict = defaultdict(dict)  # (model label, mode) -> (task, seed) -> success
        for r in (json.loads(x) for x in out.read_text().splitlines() if x.strip()):
            label = next(lab for name, lab, _ in runs if name == r["run"])
            by[(label, r["mode"])][(r["task"], r["seed"])] = r["success"]
        labels = [label for _, label, _ in self.models]
        seeds = sorted({s for eps in by.values() for _, s in eps})
        lines = [f"{self.suite} on sampled {self.layouts_kind} layouts {seeds[0]}-{seeds[-1]} ({len(seeds)} a task, in "
                 f"{len(self.seed_ranges)} runs of {layouts}); successes / episodes per run, won / lost against "
                 f"{labels[0].split(' (')[0]} in the same mode on the same layouts:", "",
                 "| model | mode | " + " | ".join(f"{a}-{a + layouts - 1}" for a in self.seed_ranges)
                 + " | all | won / lost |", "|---|---|" + "---|" * (len(self.seed_ranges) + 2)]
        for mode in self.modes:
            base = by[(labels[0], mode)]
            for label in labels:
                eps = by[(label, mode)]
                per_run = [f"{sum(ok for (_, s), ok in eps.items() if a <= s < a + layouts)}/"
                           f"{sum(a <= s < a + layouts for _, s in eps)}" for a in self.seed_ranges]
                wl = "-" if label == labels[0] else won_lost_keyed(base, eps)
                lines.append(f"| {label} | {mode} | " + " | ".join(per_run)
                             + f" | **{sum(eps.values())}/{len(eps)}** | {wl} |")
        lines += ["", "Per task (all layouts):", ""] + per_task_table(
            [(f"{label.split(' (')[0]}, {mode}", by[(label, mode)]) for mode in self.modes for label in labels])
        return lines + command_lines(script, 2, ((name, cmd) for name, _, cmd in runs))

    def main(self, doc: str, script_file: str, section: str, note: tuple[str, ...] = ()) -> None:
        """:func:`main` of the script ``script_file``: its runs gathered into <its stem>.json beside it, ``note``'s
        lines after the section's."""
        script = Path(script_file)
        out = script.with_suffix(".json")
        main(doc, lambda: gather_suite(((name, cmd) for name, _, cmd in self.runs), out, self.suite),
             lambda: self.lines(out, script.name) + list(note), section)


def command_lines(script: str, workers: int | str, runs: Iterable[tuple[str, str]]) -> list[str]:
    """The docs section's closing list: each (run directory under runs/dev, command) that ``script --gather`` reads."""
    return (["", f"Commands (each with `--workers {workers} --out runs/dev/<run>`; `{script} --gather` reads them):", ""]
            + [f"- `{name}`: `{cmd}`" for name, cmd in runs])


def main(doc: str, gather_runs: Callable[[], None], lines: Callable[[], list[str]] | dict[str, Callable[[], list[str]]],
         section: str | None = None) -> None:
    """``--gather`` runs ``gather_runs`` first; then ``lines()`` replaces ``section`` in docs/libero-planner.md (or,
    ``lines`` a dict section -> its lines function, each of those sections)."""
    ap = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--gather", action="store_true", help="read runs/dev/* into the script's JSON file first")
    if ap.parse_args().gather:
        gather_runs()
    from tcot_hybrid.markdown import update_readme_section

    for name, make in (lines.items() if isinstance(lines, dict) else ((section, lines),)):
        text = "\n".join(make())
        update_readme_section(ROOT / "docs" / "libero-planner.md", name, text)
        print(text)
