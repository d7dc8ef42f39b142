"""The paper's protocol on LIBERO (issue 16): Table 1 (success per suite) and Table 4 (the ablation) of the shipped
checkpoints on the 50 shipped init states of every task of the four suites, beside the paper's published figures,
into the <!-- libero-protocol:start/end --> sections of docs/libero-planner.md and README.md, from what
``make libero-protocol`` wrote: one ``tcot eval`` per row into docs/libero-planner/eval-protocol/ (resumable; each
run's eval.json is kept as eval-<planner>-<mode>.json for its wall time, the commits its parts started at as
eval-<planner>-<mode>.commit; the episodes, trimmed, as records.jsonl), then

    .venv/bin/python docs/libero-planner/protocol.py

A row with fewer than 500 episodes in a suite is printed as it stands, with how many it has. The paper reports
± one standard error; the intervals here are Wilson 95 % intervals (wider).

A row takes hours (GLSR on libero_10 alone about two) and a session can end mid-row, on a machine that is then gone:

    .venv/bin/python docs/libero-planner/protocol.py --save-progress [FOLDER]     # episodes.jsonl -> progress.jsonl.gz
    .venv/bin/python docs/libero-planner/protocol.py --restore-progress [FOLDER]  # and back, before tcot eval resumes

(``make libero-protocol`` restores before every row). The saved episodes keep every field but, of their events, only
the detector's calls (what the detector figures read), so a resumed row's eval.json is the same as an unbroken one's.
A row is merged into records.jsonl (and so into the tables) only once episodes.jsonl holds all of it: a rerun at a
new commit replaces the old row whole, never init state by init state.
"""
from __future__ import annotations

import argparse
import gzip
import json
from collections import Counter, defaultdict
from pathlib import Path

from summarize import SUITES, rate

from tcot_hybrid.jsonio import atomic_write_text
from tcot_hybrid.markdown import update_readme_section
from tcot_hybrid.metrics import wilson_interval

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
EVAL = HERE / "eval-protocol"
# One model per suite (the paper's TCoT row; the rows above are one model for all four, its TCoT-Multi): GLSR with
# each suite's own shipped model, one folder per suite (Makefile libero-protocol-suite)
SUITE_EVAL = HERE / "eval-protocol-suite"
# A model shipped for routed tasks alone (libero_panda_tasks_<name>, tcot_hybrid/checkpoints/task_models.json): GLSR
# and global-only on the tasks routed to it, one folder per model (Makefile libero-protocol-task)
TASK_EVAL = HERE / "eval-protocol-task"
SUITE_ROW = "GLSR, each suite's own model (the paper's TCoT row; `libero_panda_<suite>`, where shipped)"
SUITE_GLOBAL_ROW = "global trajectory only, each suite's own model (`libero_panda_<suite>`, where shipped)"
# what `tcot eval` runs without --checkpoint: the suite-model row's episodes where a suite has its own model, the
# four-suite GLSR row's elsewhere
DEFAULTS_ROW = ("GLSR at the stack's defaults (no `--checkpoint`: the model a task is routed to, else its suite's own "
                "model where one is shipped, else the four-suite model)")
DEFAULTS_GLOBAL_ROW = "global trajectory only at the stack's defaults (the same models)"
# the suite-model folders' rows, (mode, label) in table order
SUITE_MODES = (("global", SUITE_GLOBAL_ROW, DEFAULTS_GLOBAL_ROW), ("glsr", SUITE_ROW, DEFAULTS_ROW))
ORACLE = ROOT / "docs" / "eval-libero" / "oracle-shipped" / "episodes.jsonl"
PER_TASK = 50  # shipped init states a task
PER_SUITE = 10 * PER_TASK  # 10 tasks a suite
# The direct baseline runs on init states 0-1 of each task only (Makefile: 87 s an episode, 24 h for 2000)
PLANNED_PER_SUITE = {("direct", "global"): 20}
RECORD_FIELDS = ("task", "suite", "planner", "mode", "perturb", "seed", "success", "fault", "stopped_by", "steps",
                 "sim_time_s", "wall_time_s", "replans", "empty_grasps", "max_reference_limit_excess_rad",
                 "max_joint_limit_violation_rad", "checkpoint_hash", "config_hash", "fixture_seed")
# a row with an episode whose record has no fixture_seed ran before stop 64: every shipped init state of a task with
# the fixtures where the scene's build placed them (one draw), where LIBERO's evaluation draws them for every state
ONE_DRAW = " °"
ONE_DRAW_NOTE = ("° ran before stop 64, every shipped init state of a task with the fixtures (cabinets, stoves, racks, "
                 "the caddy) at one draw, the scene build's; LIBERO's evaluation resets the env, which draws them "
                 "afresh (+-1 cm), before it sets each state, and so does this stack since (docs/libero.md).")


def one_draw(eps: list[dict]) -> str:
    """:data:`ONE_DRAW` for episodes any of which ran with the fixtures at the scene build's placement, else ''."""
    return ONE_DRAW if any(e.get("fixture_seed") is None for e in eps) else ""
# (planner, supervisor mode) per row of ours, in Table 4's order, and how the paper names the row
ROWS = ((("direct", "global"), "direct baseline (next action every step; the paper's OpenVLA row)"),
        (("learned", "global"), "global trajectory only"),
        (("learned", "local"), "local trajectory only"),
        (("learned", "glsr"), "GLSR (Algorithm 1)"),
        (("learned", "glsr_reset"), "GLSR, reset-retry variant (the paper's released code)"))
# The paper's Table 1 (discrete actions, ± s.e.) and Table 2 (continuous actions): spatial, object, goal, long, average
PAPER = (("OpenVLA (paper Table 1)", (0.847, 0.884, 0.792, 0.537, 0.765)),
         ("TCoT (paper Table 1)", (0.910, 0.948, 0.788, 0.668, 0.829)),
         ("TCoT-Multi: one model, four suites (paper Table 1)", (0.900, 0.870, 0.850, 0.710, 0.833)),
         ("OpenVLA-OFT (paper Table 2)", (0.969, 0.981, 0.955, 0.911, 0.954)),
         ("TCoT-OFT (paper Table 2)", (0.975, 0.988, 0.950, 0.935, 0.962)))
# The paper's Table 4 (average success rate, ± s.e.) against our row of the same design
PAPER_ABLATION = {("direct", "global"): "OpenVLA 0.765 ± .006", ("learned", "global"): "0.786 ± .005",
                  ("learned", "local"): "0.773 ± .009", ("learned", "glsr"): "0.829 ± .007"}


def _read(path: Path) -> list[dict]:
    return [json.loads(x) for x in path.read_text().splitlines() if x.strip()] if path.is_file() else []


def _records(folder: Path = EVAL) -> list[dict]:
    """The episodes, trimmed to the fields these tables use. ``tcot eval``'s episodes.jsonl (every event of every
    episode, 50 MB a row, kept out of git: it is what a resumed run reads) is merged into records.jsonl (committed):
    a row episodes.jsonl holds whole (:func:`_complete_rows`) replaces that row's episodes (unless it ran with the
    fixtures at the build's one draw and records.jsonl's ran with each state's own), and rows only records.jsonl
    holds (a row run on another machine or before a fresh checkout) are kept."""
    def key(r: dict) -> tuple:
        return r["task"], r["planner"], r["mode"], r["perturb"], r["seed"]

    merged = {key(r): r for r in _read(folder / "records.jsonl")}
    full = _complete_rows(_read(folder / "episodes.jsonl"), folder)
    if not full:
        return list(merged.values())
    # an episodes.jsonl from an older checkout (its rows run with the build's one fixture draw) never replaces a row
    # run since with each state's own draw: such a row is left out whole, and its saved progress kept
    rows: dict = defaultdict(list)
    for e in full:
        rows[_run_row(e)].append({k: e.get(k) for k in RECORD_FIELDS})
    merged_rows = set()
    for row, incoming in sorted(rows.items()):
        if any(r.get("fixture_seed") is None and (merged.get(key(r)) or {}).get("fixture_seed") is not None
               for r in incoming):
            print(f"{folder.name}: the {row[0]} {row[1]} row in episodes.jsonl ran with the fixtures at the build's "
                  "one draw; records.jsonl's run with each state's own draw is kept")
            continue
        merged.update({key(r): r for r in incoming})
        merged_rows.add(row)
    _drop_saved_progress(folder, merged_rows)
    records = sorted(merged.values(), key=lambda r: (r["planner"], r["mode"], r["perturb"], r["suite"], r["task"],
                                                     r["seed"]))
    atomic_write_text(folder / "records.jsonl", "".join(json.dumps(r) + "\n" for r in records))
    return records


def _run_row(e: dict) -> tuple[str, str, str]:
    """The run an episode belongs to: (planner, mode, perturbation)."""
    return e["planner"], e["mode"], e["perturb"]


def _row_size(row: tuple[str, str], folder: Path) -> int:
    """Episodes in a whole row of ``folder``: every planned init state of the four suites, of a suite-model folder's
    one suite, or of the tasks routed to a task-model folder's model."""
    if folder.parent == TASK_EVAL:
        return len(routed_tasks(folder.name)) * PER_TASK
    suites = {folder.name} if folder.parent == SUITE_EVAL else set(SUITES)
    return len(suites) * PLANNED_PER_SUITE.get(row, PER_SUITE)


def routed_tasks(stem: str) -> list[str]:
    """The tasks tcot_hybrid/checkpoints/task_models.json routes to the shipped checkpoint ``stem``."""
    from tcot_hybrid.learning.checkpoint import task_models

    return sorted(t for t, s in task_models("libero_panda").items() if s == stem)


def _complete_rows(episodes: list[dict], folder: Path) -> list[dict]:
    """The episodes of the rows episodes.jsonl holds whole (every planned init state of every suite the row covers:
    the four here, a suite-model folder its one suite); a row still running is named and left out, so the tables
    keep its last complete run instead of mixing two runs' configurations.

    ``tcot eval`` appends, and a resumed run never repeats an episode it has: in a row's lines, an init state that
    comes again starts a new run of the row (other defaults, code or checkpoint), and the row's latest run is what
    follows the last such restart. A rerun half done is therefore in progress, and the run before it is not filled
    in around it. (A run abandoned before it was complete and followed by another is told apart only from the first
    init state the second repeats.)"""
    by: dict = defaultdict(list)
    for e in episodes:
        by[_run_row(e)].append(e)
    out = []
    for (planner, mode, perturb), eps in sorted(by.items()):
        latest: dict = {}
        for e in eps:
            if (e["task"], e["seed"]) in latest:
                latest = {}  # a new run of this row starts here
            latest[(e["task"], e["seed"])] = e
        want = _row_size((planner, mode), folder)
        if len(latest) >= want:
            out += latest.values()
        else:
            print(f"{folder.name}: the {planner} {mode} row is in progress in episodes.jsonl ({len(latest)} of {want} "
                  "episodes): not merged until it is complete")
    return out


def _slim(episode: dict) -> dict:
    """An episode with, of its events, only the detector's calls (the fields detector_metrics reads)."""
    keep = ("kind", "step", "p_success", "true_success")
    return {**episode, "events": [{k: ev[k] for k in keep if k in ev} for ev in episode.get("events", [])
                                  if "p_success" in ev]}


def save_progress(folder: Path) -> Path:
    """episodes.jsonl (what a resumed ``tcot eval`` reads) as progress.jsonl.gz, slimmed (:func:`_slim`), to commit."""
    episodes = _read(folder / "episodes.jsonl")
    if not episodes:
        raise SystemExit(f"{folder / 'episodes.jsonl'}: no episodes to save")
    out = folder / "progress.jsonl.gz"
    tmp = out.with_suffix(".tmp")
    with gzip.open(tmp, "wt") as f:
        f.writelines(json.dumps(_slim(e)) + "\n" for e in episodes)
    tmp.replace(out)
    rows = Counter((e["planner"], e["mode"]) for e in episodes)
    print(f"{out}: {len(episodes)} episodes ({', '.join(f'{p} {m} {n}' for (p, m), n in sorted(rows.items()))}), "
          f"{out.stat().st_size / 1e6:.1f} MB")
    return out


def _drop_saved_progress(folder: Path, rows: set) -> None:
    """Rows now merged into records.jsonl leave progress.jsonl.gz (removed once it holds none in progress)."""
    src = folder / "progress.jsonl.gz"
    if not src.is_file():
        return
    with gzip.open(src, "rt") as f:
        lines = [x for x in f if x.strip()]
    left = [x for x in lines if _run_row(json.loads(x)) not in rows]
    if not left:
        src.unlink()
    elif len(left) < len(lines):
        with gzip.open(src, "wt") as f:
            f.writelines(left)


def restore_progress(folder: Path) -> int:
    """Episodes of progress.jsonl.gz that episodes.jsonl lacks (by key), appended to it; returns how many."""
    src = folder / "progress.jsonl.gz"
    if not src.is_file():
        return 0
    log = folder / "episodes.jsonl"
    have = {e["key"] for e in _read(log)}
    with gzip.open(src, "rt") as f:
        missing = [line for line in f if line.strip() and json.loads(line)["key"] not in have]
    with open(log, "a") as f:
        f.writelines(missing)
    print(f"{log}: {len(missing)} episodes restored from {src.name} ({len(have)} already there)")
    return len(missing)


def start_row(folder: Path, planner: str, mode: str, commit: str) -> None:
    """Before a row's ``tcot eval``: ``commit`` appended to eval-<planner>-<mode>.started, so that a row cut off with
    the session and resumed at another commit names every commit its episodes ran at (the file is committed with
    the saved progress)."""
    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / f"eval-{planner}-{mode}.started", "a") as f:
        f.write(commit + "\n")


def keep_row(folder: Path, planner: str, mode: str, commit: str) -> bool:
    """After a row's ``tcot eval``: its eval.json kept as eval-<planner>-<mode>.json and, as its .commit, the commits
    its parts started at (eval-<planner>-<mode>.started, :func:`start_row`; ``commit`` when there is none), in order,
    but only if the run ran an episode; a row that was already complete (every episode read back from the folder)
    keeps the wall time and the commits of the runs that made it. The .started file is removed either way. Returns
    whether the row's files were written."""
    started = folder / f"eval-{planner}-{mode}.started"
    lines = [x.strip() for x in started.read_text().splitlines() if x.strip()] if started.is_file() else []
    parts = [c for i, c in enumerate(lines) if i == 0 or c != lines[i - 1]]  # a part started twice at one commit
    started.unlink(missing_ok=True)
    text = (folder / "eval.json").read_text()
    result = json.loads(text)
    if result["ran_now"] == 0:
        print(f"{folder}: {planner} {mode} ran no episode (all {result['episodes']} in the folder already); "
              f"eval-{planner}-{mode}.json/.commit kept as they were")
        return False
    # a run in one part: the commit it started at (commits can land while a row runs)
    commits = (parts if result["ran_now"] < result["episodes"] else parts[-1:]) or [commit]
    atomic_write_text(folder / f"eval-{planner}-{mode}.json", text)
    atomic_write_text(folder / f"eval-{planner}-{mode}.commit", ", then ".join(commits) + "\n")
    print(f"{folder}: {planner} {mode} ran {result['ran_now']} of {result['episodes']} episodes at "
          f"{', then '.join(commits)}")
    return True


def _model_folders(root: Path) -> list[Path]:
    """The one-model folders under ``root`` (SUITE_EVAL: one per suite; TASK_EVAL: one per task model)."""
    return sorted(p for p in root.glob("*") if p.is_dir()) if root.is_dir() else []


def _one_model_episodes(folder: Path, key: str, allowed: set[str], what: str) -> list[dict]:
    """Global-only and GLSR episodes of a one-model folder, refused (naming them) if any episode's ``key`` (suite or
    task) is not in ``allowed`` or they come from more than one checkpoint (as in :func:`_rows`); ``what`` says what
    the folder must hold."""
    eps = [e for e in _records(folder) if e["perturb"] == "none" and e["mode"] in ("glsr", "global")]
    strays = sorted({e[key] for e in eps} - allowed)
    hashes = sorted({e["checkpoint_hash"] for e in eps})
    if strays or len(hashes) > 1:
        raise SystemExit(f"{folder}: holds episodes of {key}s {strays} or of {len(hashes)} checkpoints "
                         f"({', '.join(map(str, hashes))}); {what} per folder")
    return eps


def _task_model_records() -> dict[str, list[dict]]:
    """Global-only and GLSR episodes of each task-model folder, by checkpoint stem (the folder's name): the tasks
    task_models.json routes to that model, run with it."""
    return {folder.name: _one_model_episodes(folder, "task", set(routed_tasks(folder.name)),
                                             "the tasks routed to its model and that model alone")
            for folder in _model_folders(TASK_EVAL)}


def _suite_model_records() -> list[dict]:
    """Global-only and GLSR episodes of the suite-model rows: each suite's folder holds that suite's tasks run with
    its own model (one checkpoint per folder, as in :func:`_rows`)."""
    return [e for folder in _model_folders(SUITE_EVAL)
            for e in _one_model_episodes(folder, "suite", {folder.name}, "one suite and its own model")]


def _rows() -> dict[tuple[str, str], list[dict]]:
    """Episodes per (planner, mode); one checkpoint per row (a folder resumed with another checkpoint would mix two
    networks in one figure: refused, naming both)."""
    by: dict = defaultdict(list)
    for e in _records():
        if e["perturb"] == "none":
            by[(e["planner"], e["mode"])].append(e)
    for key, eps in by.items():
        hashes = sorted({e["checkpoint_hash"] for e in eps})
        if len(hashes) > 1:
            raise SystemExit(f"{EVAL}: the {key[0]} {key[1]} episodes come from {len(hashes)} checkpoints "
                             f"({', '.join(map(str, hashes))}); evaluate one checkpoint per folder")
    return by


def _suite_counts(eps: list[dict]) -> dict[str, list[int]]:
    got: dict = defaultdict(lambda: [0, 0])
    for e in eps:
        if e["fault"] and e["success"]:
            raise SystemExit(f"{e['task']} seed {e['seed']}: a faulted episode is recorded as a success")
        got[e["suite"]][0] += bool(e["success"])
        got[e["suite"]][1] += 1
    return got


def _average(got: dict[str, list[int]]) -> str:
    """The paper's average: the mean of the four suites' rates, with the Wilson interval of the pooled count (the same
    rate when every suite has as many episodes; a partial row with unequal suites shows the pooled rate, so marked)."""
    if not all(got[s][1] for s in SUITES):
        return "-"
    k = sum(got[s][0] for s in SUITES)
    n = sum(got[s][1] for s in SUITES)
    if len({got[s][1] for s in SUITES}) > 1:
        return f"{rate(k, n)} pooled (suites unequal)"
    lo, hi = wilson_interval(k, n)
    return f"**{k / n:.3f}** [{lo:.2f}, {hi:.2f}] n={n}"


def _checkpoint_note(eps: list[dict], shipped_stem: str) -> str:
    """The checkpoint a row's episodes loaded (one per row: :func:`_rows`), and whether it is the one shipped now in
    tcot_hybrid/checkpoints/``shipped_stem``.safetensors (a row of a replaced checkpoint stays in the tables until
    the new one's row is complete)."""
    from tcot_hybrid.episode import file_digest

    ran = eps[0]["checkpoint_hash"]
    shipped = ROOT / "tcot_hybrid" / "checkpoints" / f"{shipped_stem}.safetensors"
    now = file_digest(shipped) if shipped.is_file() else None
    return f"checkpoint `{ran}`" + ("" if ran == now else f", **not the one shipped now** (`{now}`)")


def _provenance(planner: str, mode: str, folder: Path = EVAL) -> str | None:
    """How a row's last run went (eval-<planner>-<mode>.json, written when it finished) and the commit it ran at
    (eval-<planner>-<mode>.commit: the commits its parts started at, :func:`keep_row`)."""
    parts = []
    p = folder / f"eval-{planner}-{mode}.json"
    if p.is_file():
        r = json.loads(p.read_text())
        parts.append(f"{r['ran_now']} episodes in {r['wall_time_s'] / 60:.1f} min wall with {r['workers']} workers"
                     + (f" ({r['episodes'] - r['ran_now']} already in the folder)" if r["episodes"] > r["ran_now"]
                        else ""))
    commit = p.with_suffix(".commit")
    if commit.is_file():
        parts.append(f"at commit {commit.read_text().strip()}")
    return ", ".join(parts) or None


def defaults_episodes(multi: list[dict], suite_eps: list[dict], task_eps: dict[str, list[dict]] | None = None
                      ) -> list[dict]:
    """A defaults row of one mode: each task's episodes from the row of the model `tcot eval` loads for it without
    --checkpoint (tcot_hybrid.learning.checkpoint.default_checkpoint: a task routed in task_models.json, else its
    suite's own model, else the four-suite one): the suite-model row's (``suite_eps``), the four-suite row's
    (``multi``) or the row of the task model it is routed to (``task_eps``, by checkpoint stem); a task whose model
    no row ran is left out (the row's n says so)."""
    from tcot_hybrid.learning.checkpoint import default_checkpoint

    task_eps = task_eps or {}
    out = []
    for task in sorted({e["task"] for e in multi + suite_eps}):
        suite = task.split(":")[0]
        stem = default_checkpoint("libero_panda", suite=suite, task=task).stem
        src = (multi if stem == "libero_panda_default" else suite_eps if stem == f"libero_panda_{suite}"
               else task_eps.get(stem, []))
        out += [e for e in src if e["task"] == task]
    return out


def table1_lines(by, suite_eps: list[dict], task_eps: dict[str, list[dict]]) -> list[str]:
    lines = ["**Table 1 form: success on the shipped init states** (`make libero-protocol`, "
             "`docs/libero-planner/eval-protocol/`; ours: success [Wilson 95 % interval] n; the paper's: mean of 500 "
             "episodes per suite, its ± one standard error is 0.2-1.4 points):", "",
             "| method | " + " | ".join(SUITES) + " | average |", "|" + "---|" * (len(SUITES) + 2)]
    for name, figs in PAPER:
        lines.append(f"| {name} | " + " | ".join(f"{f:.3f}" for f in figs[:-1]) + f" | {figs[-1]:.3f} |")
    for key, label in ROWS:
        eps = by.get(key)
        if not eps:
            lines.append(f"| ours: {label} | " + " | ".join("not run" for _ in SUITES) + " | - |")
            continue
        got = _suite_counts(eps)
        ns = [got[s][1] for s in SUITES]
        planned = PLANNED_PER_SUITE.get(key, PER_SUITE)
        partial = f" (so far: {min(ns)}-{max(ns)} of {planned} per suite)" if min(ns) < planned else ""
        if planned < PER_SUITE:
            partial += f" (init states 0-{planned // 10 - 1} of each task)"
        lines.append(f"| ours: {label}{partial}{one_draw(eps)} | "
                     + " | ".join(rate(*got[s]) for s in SUITES) + f" | {_average(got)} |")
    defaults = {}
    for mode, label, defaults_label in SUITE_MODES:
        own = [e for e in suite_eps if e["mode"] == mode]
        if not own:
            continue
        got = _suite_counts(own)
        lines.append(f"| ours: {label}{one_draw(own)} | "
                     + " | ".join(rate(*got[s]) if got[s][1] else "-" for s in SUITES) + f" | {_average(got)} |")
        multi = by.get(("learned", mode))
        if multi:
            routed_eps = {stem: [e for e in eps if e["mode"] == mode] for stem, eps in task_eps.items()}
            picked = defaults_episodes(multi, own, routed_eps)
            defaults[mode] = got = _suite_counts(picked)
            lines.append(f"| ours: {defaults_label}{one_draw(picked)} | " + " | ".join(rate(*got[s]) for s in SUITES)
                         + f" | {_average(got)} |")
    oracle_eps = [e for e in _read(ORACLE) if e["perturb"] == "none"]
    oracle = _suite_counts(oracle_eps)
    if oracle:
        lines.append(f"| oracle: privileged script (`docs/eval-libero/oracle-shipped/`){one_draw(oracle_eps)} | "
                     + " | ".join(rate(*oracle[s]) for s in SUITES) + f" | {_average(oracle)} |")
    lines.append("")
    if any(ONE_DRAW in x for x in lines):
        lines += [ONE_DRAW_NOTE, ""]
    glob = by.get(("learned", "global"))
    for which, got in (("the four-suite model", _suite_counts(glob) if glob else None),
                       ("the stack's defaults", defaults.get("global"))):
        if not got or not oracle:
            continue
        shares = [f"{s} {got[s][0] / got[s][1] / (oracle[s][0] / oracle[s][1]):.2f}" if got[s][1] == PER_SUITE
                  else f"{s} not whole yet ({got[s][1]} of {PER_SUITE} episodes)" for s in SUITES if oracle[s][0]]
        lines.append(f"- Global-only ({which}) as a share of the oracle's success, per suite (the issue's bar: at "
                     "least 0.80): " + ", ".join(shares) + ".")
    for key, label in ROWS:
        eps = by.get(key)
        if not eps:
            continue
        how = _provenance(*key)
        stops = sum(e["stopped_by"] == "detector" and not e["success"] for e in eps)
        faults = Counter(str(e["fault"])[:60] for e in eps if e["fault"])
        why = ", ".join(f"{k} x{v}" for k, v in faults.most_common())
        worst = max(e["max_reference_limit_excess_rad"] for e in eps)
        # what the row costs without the gaps between its parts (runs cut off and resumed): the episodes' own wall times
        work_min = sum(e["wall_time_s"] for e in eps) / 60
        by_suite = ", ".join(f"{s} {sum(e['wall_time_s'] for e in eps if e['suite'] == s) / 60:.0f}" for s in SUITES)
        shipped_stem = "libero_panda_direct_default" if key[0] == "direct" else "libero_panda_default"
        lines.append(f"- {label}: {len(eps)} episodes, {_checkpoint_note(eps, shipped_stem)}"
                     + (f"; run: {how}" if how else "")
                     + f"; the episodes' own wall times sum to {work_min:.0f} worker-min ({by_suite}), "
                       f"{work_min / 2:.0f} min on 2 workers before scene builds and worker starts"
                     + f"; {sum(faults.values())} faulted" + (f" ({why})" if why else "")
                     + ", none counted as a success; worst commanded joint-limit excess "
                       f"{worst:.4f} rad" + (f"; {stops} ended on a detector verdict while the task was not done"
                                             if key[1].startswith("glsr") else "") + ".")
    for mode, label, defaults_label in SUITE_MODES:
        for folder in _model_folders(SUITE_EVAL):
            eps = [e for e in suite_eps if e["suite"] == folder.name and e["mode"] == mode]
            if not eps:
                continue
            how = ", ".join(x for x in (f"{len(eps)} episodes", _provenance("learned", mode, folder)) if x)
            how += ", " + _checkpoint_note(eps, f"libero_panda_{folder.name}")
            lines.append(f"- {label.split(' (')[0]}, {folder.name} (`{folder.relative_to(ROOT)}/`): {how}; "
                         f"{sum(bool(e['fault']) for e in eps)} faulted, none counted as a success.")
        multi = by.get(("learned", mode))
        own = sorted({e["suite"] for e in suite_eps if e["mode"] == mode})
        if own and multi:  # a defaults row borrows the four-suite row's episodes where no own model ran
            from tcot_hybrid.learning.checkpoint import task_models

            routed = "".join(f"; {t.split(':', 1)[1]} ({t.split(':')[0]}) from the row of `{stem}`, the model it is "
                             "routed to (tcot_hybrid/checkpoints/task_models.json)"
                             for t, stem in sorted(task_models("libero_panda").items()))
            lines.append(f"- {defaults_label.split(' (')[0]}: {', '.join(own)} from the suite models' rows, the other "
                         f"suites from the four-suite {mode} row ({_checkpoint_note(multi, 'libero_panda_default')})"
                         f"{routed}.")
    for folder in _model_folders(TASK_EVAL):
        for mode, label, _ in SUITE_MODES:
            eps = [e for e in task_eps.get(folder.name, []) if e["mode"] == mode]
            if eps:
                how = ", ".join(x for x in (f"{len(eps)} episodes", _provenance("learned", mode, folder)) if x)
                lines.append(f"- {label.split(',')[0]}, the tasks routed to `{folder.name}` (`{folder.relative_to(ROOT)}/`): "
                             f"{how}, {_checkpoint_note(eps, folder.name)}; {sum(bool(e['fault']) for e in eps)} "
                             "faulted, none counted as a success.")
    lines.append("- Per task: `docs/libero-planner/eval-protocol/per_task.md`.")
    det = EVAL / "eval-learned-glsr.json"
    if det.is_file():
        d = json.loads(det.read_text())["detector"].get("learned")
        if d:
            lines.append(f"- Failure detector in the GLSR run: AUROC {d['auroc']} over {d['calls']} frames ("
                         f"{d['in_episode_frames']} judged while the episodes ran, the rest probes after a success; "
                         f"{d['positives']} with the task done); false-alarm rate {d['false_alarm_rate']} (successful "
                         f"episodes in which a probe after the success said not done, of {d['successful_episodes_probed']}"
                         f"); detection latency {d['detection_latency_steps']} steps.")
    return lines


def table4_lines(by) -> list[str]:
    lines = ["", "**Table 4 form: the ablation** (average over the four suites, as above):", "",
             "| row | global | local | GLSR | ours | the paper |", "|---|---|---|---|---|---|"]
    marks = {("direct", "global"): ("-", "-", "-"), ("learned", "global"): ("✓", "-", "-"),
             ("learned", "local"): ("-", "✓", "-"), ("learned", "glsr"): ("✓", "✓", "✓"),
             ("learned", "glsr_reset"): ("✓", "✓", "✓ (reset)")}
    for key, label in ROWS:
        eps = by.get(key)
        ours = _average(_suite_counts(eps)) if eps else "not run"
        lines.append(f"| {label} | " + " | ".join(marks[key]) + f" | {ours} | {PAPER_ABLATION.get(key, '-')} |")
    return lines


def per_task_lines(by, suite_eps: list[dict], task_eps: dict[str, list[dict]]) -> list[str]:
    """Successes of every row per task (k of n shipped init states), for eval-protocol/per_task.md: where a suite's
    figure is lost. A report of the test set, not a tuning signal (docs/seeds.md)."""
    oracle = [e for e in _read(ORACLE) if e["perturb"] == "none"]
    cols = ([(label.split(" (")[0], by[key]) for key, label in ROWS if by.get(key)]
            + [(label.split(" (")[0], [e for e in suite_eps if e["mode"] == mode]) for mode, label, _ in SUITE_MODES
               if any(e["mode"] == mode for e in suite_eps)]
            + [(f"{label.split(',')[0]}, the model a task is routed to", eps) for mode, label, _ in SUITE_MODES
               if (eps := [e for v in task_eps.values() for e in v if e["mode"] == mode])]
            + [("oracle", oracle)])
    cells: dict = defaultdict(dict)
    for name, eps in cols:
        for e in eps:
            k, n = cells[e["task"]].get(name, (0, 0))
            cells[e["task"]][name] = (k + bool(e["success"]), n + 1)
    lines = ["# Success per task on the shipped init states", "",
             "Written by `docs/libero-planner/protocol.py` from `records.jsonl` (successes of the episodes run; "
             "the test set: read, never tuned on).", "",
             "| suite | task | " + " | ".join(name for name, _ in cols) + " |", "|" + "---|" * (len(cols) + 2)]
    for task in sorted(cells, key=lambda t: (SUITES.index(t.split(":")[0]), t)):
        suite, name = task.split(":", 1)
        lines.append(f"| {suite} | {name} | " + " | ".join(
            "%d/%d" % cells[task][c] if c in cells[task] else "-" for c, _ in cols) + " |")
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    act = ap.add_mutually_exclusive_group()
    act.add_argument("--save-progress", metavar="FOLDER", nargs="?", const=str(EVAL), type=Path,
                     help="write FOLDER/episodes.jsonl, slimmed, to FOLDER/progress.jsonl.gz (default folder: %(const)s)")
    act.add_argument("--restore-progress", metavar="FOLDER", nargs="?", const=str(EVAL), type=Path,
                     help="append FOLDER/progress.jsonl.gz's episodes missing from FOLDER/episodes.jsonl")
    act.add_argument("--start-row", nargs=4, metavar=("FOLDER", "PLANNER", "MODE", "COMMIT"),
                     help="before a row's tcot eval: append COMMIT to FOLDER/eval-PLANNER-MODE.started")
    act.add_argument("--routed-tasks", metavar="STEM",
                     help="print the tasks task_models.json routes to the shipped checkpoint STEM, comma-separated")
    act.add_argument("--keep-row", nargs=4, metavar=("FOLDER", "PLANNER", "MODE", "COMMIT"),
                     help="after a row's tcot eval: keep FOLDER/eval.json as eval-PLANNER-MODE.json and, as its "
                          ".commit, the commits its parts started at (COMMIT for a run in one part), unless the run "
                          "ran no episode (the row's files then stay as they were)")
    args = ap.parse_args()
    if args.start_row:
        folder, planner, mode, commit = args.start_row
        start_row(Path(folder), planner, mode, commit)
        return
    if args.routed_tasks:
        tasks = routed_tasks(args.routed_tasks)
        if not tasks:
            raise SystemExit(f"no task is routed to {args.routed_tasks!r} (tcot_hybrid/checkpoints/task_models.json)")
        print(",".join(tasks))
        return
    if args.keep_row:
        folder, planner, mode, commit = args.keep_row
        keep_row(Path(folder), planner, mode, commit)
        return
    if args.save_progress:
        save_progress(args.save_progress)
        return
    if args.restore_progress:
        restore_progress(args.restore_progress)
        return
    by = _rows()
    suite_eps = _suite_model_records()  # reads (and rewrites) each suite folder's records once
    task_eps = _task_model_records()  # and each task-model folder's
    atomic_write_text(EVAL / "per_task.md", "\n".join(per_task_lines(by, suite_eps, task_eps)) + "\n")
    text = "\n".join(table1_lines(by, suite_eps, task_eps) + table4_lines(by)) + "\n"
    for target in (ROOT / "docs" / "libero-planner.md", ROOT / "README.md"):
        update_readme_section(target, "libero-protocol", text)
    print(text)


if __name__ == "__main__":
    main()
