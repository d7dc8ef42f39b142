"""Figures for RELIABILITY.md rows 23-28 (issue 18), measured through the `tcot` command as a user runs it.

    .venv/bin/python docs/reliability/harden.py      # ~3 min; as root it also mounts small tmpfs disks

Writes docs/reliability/harden.md, the reach maps docs/reliability/reach_*.png, and the tables into the
<!-- harden:start/end --> section of docs/reliability.md. Every figure there comes from this script.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs" / "reliability"
PY = sys.executable
ENV = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}

# Runs `tcot ARGS` in a fresh interpreter and reports its own peak RSS (VmHWM: ru_maxrss would include
# the forking parent's), wall time, exit code and stderr size.
WRAP = """
import sys, time, json
t0 = time.perf_counter()
from tcot_hybrid.cli import main
import io, contextlib
err = io.StringIO()
with contextlib.redirect_stderr(err):
    try:
        rc = main(sys.argv[1:])
    except SystemExit as e:
        rc = e.code if isinstance(e.code, int) else 1
    except BaseException as e:
        rc, _ = 99, err.write(f"CRASH {type(e).__name__}: {str(e)[:300]}")
hwm = next(int(l.split()[1]) for l in open('/proc/self/status') if l.startswith('VmHWM:'))
print(json.dumps({"rc": rc, "s": round(time.perf_counter() - t0, 2), "rss_mb": round(hwm / 1024),
                  "err_chars": len(err.getvalue()), "err": err.getvalue().strip()[:800]}))
"""


def clean(msg: str, tmp: Path, n: int = 120) -> str:
    """One table-safe line: temp paths as TMP, tyro's box drawing and newlines gone, no pipes or backticks."""
    msg = msg.replace(str(tmp), "TMP")
    if "Error parsing" in msg:
        msg = msg[msg.index("Error parsing"):]
    for ch in "╭╮╰╯│─":
        msg = msg.replace(ch, " ")
    msg = " ".join(msg.split()).replace("|", "/").replace("`", "'")
    return msg[:n]


def tcot(*args: str, timeout: int = 300) -> dict:
    r = subprocess.run([PY, "-c", WRAP, *args], capture_output=True, text=True, timeout=timeout, env=ENV, cwd=ROOT)
    try:
        return json.loads(r.stdout.strip().splitlines()[-1])
    except (IndexError, json.JSONDecodeError):
        return {"rc": r.returncode, "s": None, "rss_mb": None, "err_chars": len(r.stderr), "err": r.stderr[-160:]}


def bombs(tmp: Path) -> dict[str, Path]:
    items = ["&a0 [x, x, x, x, x, x, x, x, x]"] + [
        f"&a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, 8)]
    files = {
        "YAML alias bomb (issue 18, 43M items expanded)": ("bomb.yaml", "task: goal_cube_on_plate\nseed: ["
                                                           + ", ".join(items) + "]\n"),
        "YAML alias bomb of mappings (10^8 keys)": ("mbomb.yaml", "a0: &a0 {x: 1}\n" + "".join(
            f"a{i}: &a{i} {{{', '.join(f'k{k}: *a{i - 1}' for k in range(10))}}}\n" for i in range(1, 9))),
        "255 KiB flat list (just under the size limit)": ("flat.yaml", "seed: [" + "1, " * 87_000 + "1]\n"),
        "60,000-deep nested YAML list": ("deep.yaml", "seed: " + "[" * 60_000 + "]" * 60_000 + "\n"),
        "100,000-deep nested JSON": ("deep.json", '{"seed": ' + "[" * 100_000 + "]" * 100_000 + "}"),
        "100,000-deep nested TOML": ("deep.toml", "seed = " + "[" * 100_000 + "]" * 100_000 + "\n"),
        "255 KiB string where an int belongs": ("long.yaml", "seed: " + "x" * 261_000 + "\n"),
        "duplicate key": ("dup.yaml", "seed: 1\ntask: goal_cube_in_bowl\nseed: 2\n"),
    }
    out = {}
    for what, (name, text) in files.items():
        (tmp / name).write_text(text)
        out[what] = tmp / name
    big = tmp / "fifty_mb.yaml"
    with big.open("w") as f:
        f.write("seed: [" + ("1, " * 100_000) * 167 + "1]\n")
    out["50 MB config, 16.7M-item list (issue 18)"] = big
    out["a directory as --config"] = tmp
    out["/dev/zero as --config"] = Path("/dev/zero")
    return out


def row23(tmp: Path) -> list[str]:
    rows = ["| input | size | exit | peak RSS [MB] | time [s] | error chars | message |", "|---|---|---|---|---|---|---|"]
    for what, path in bombs(tmp).items():
        size = path.stat().st_size if path.is_file() and path != Path("/dev/zero") else 0
        m = tcot("run", "--config", str(path), "--out", str(tmp / "o"))
        msg = clean(m["err"], tmp, 110)
        rows.append(f"| {what} | {size:,} B | {m['rc']} | {m['rss_mb']} | {m['s']} | {m['err_chars']} | `{msg}` |")
    return rows


def mount(path: Path, opts: str) -> bool:
    path.mkdir(parents=True, exist_ok=True)
    return (shutil.which("mount") is not None and os.geteuid() == 0 and
            subprocess.run(["mount", "-t", "tmpfs", "-o", opts, "tmpfs", str(path)], capture_output=True).returncode == 0)


def fill(folder: Path) -> None:
    with (folder / "filler").open("wb", buffering=0) as f:
        for size in (65536, 4096, 1):
            try:
                while True:
                    f.write(b"\0" * size)
            except OSError:
                pass


def row24(tmp: Path) -> list[str]:
    rows = ["| output problem | command | exit | before the episode | result |", "|---|---|---|---|---|"]
    afile = tmp / "afile"
    afile.write_text("")
    cases = [("`--out` is an existing file", ["run", "--task", "goal_cube_on_plate", "--out", str(afile)])]
    vdir = tmp / "vdir"
    vdir.mkdir()
    cases.append(("`--video` is a directory", ["run", "--task", "goal_cube_on_plate", "--out", str(tmp / "ok"),
                                               "--video", str(vdir)]))
    ro, full = tmp / "ro", tmp / "full"
    mounted = mount(ro, "size=1m,ro") and mount(full, "size=256k")
    if mounted:
        fill(full)
        for label, where in (("read-only", ro), ("full disk", full)):
            cases += [(f"{label} `--out` (run)", ["run", "--task", "goal_cube_on_plate", "--out", str(where / "r")]),
                      (f"{label} `--video`", ["run", "--task", "goal_cube_on_plate", "--out", str(tmp / "ok"),
                                               "--video", str(where / "v.mp4")]),
                      (f"{label} `--out` (eval)", ["eval", "--tasks", "goal_cube_on_plate", "--episodes", "1",
                                                    "--out", str(where / "e")]),
                      (f"{label} `--out` (collect)", ["collect", "--tasks", "goal_cube_on_plate", "--episodes-per-task",
                                                       "1", "--quiet", "--out", str(where / "d.hdf5")]),
                      (f"{label} `--out` (train)", ["train", "--out", str(where / "p.safetensors")])]
    ck = tmp / "trained.safetensors"
    ck.write_bytes(b"x")
    cases.append(("`tcot train --out` an existing checkpoint", ["train", "--out", str(ck)]))
    for label, args in cases:
        m = tcot(*args)
        before = "yes" if m["s"] is not None and m["s"] < 10 else "?"
        msg = clean(m["err"], tmp, 110)
        rows.append(f"| {label} | `tcot {args[0]}` | {m['rc']} | {before} ({m['s']} s) | `{msg}` |")
    # symlinked record and a record over a full disk
    from tcot_hybrid.episode import write_record
    from tcot_hybrid.errors import OutputError

    precious = tmp / "precious.txt"
    precious.write_text("keep")
    sl = tmp / "sl"
    sl.mkdir()
    (sl / "episode.json").symlink_to(precious)
    write_record({"task": "t"}, sl)
    rows.append(f"| `episode.json` is a symlink | `write_record` | - | - | target kept: {precious.read_text() == 'keep'}, "
                f"link replaced by a file: {not (sl / 'episode.json').is_symlink()} |")
    if mounted:
        disk = tmp / "small"
        mount(disk, "size=256k")
        write_record({"task": "t", "events": []}, disk)
        before = (disk / "episode.json").read_bytes()
        fill(disk)
        try:
            write_record({"task": "t", "events": [{"kind": "x", "i": i} for i in range(20_000)]}, disk)
            outcome = "written"
        except OutputError as exc:
            outcome = f"OutputError ({str(exc).split(': ', 1)[-1][:60]})"
        same = (disk / "episode.json").read_bytes() == before
        rows.append(f"| record over a full disk | `write_record` | - | - | {outcome}; previous record intact: {same}; "
                    f"temp files left: {len([p for p in disk.iterdir() if p.name.startswith('.')])} |")
        subprocess.run(["umount", "-l", str(disk)], capture_output=True)
        for d in (ro, full):
            subprocess.run(["umount", "-l", str(d)], capture_output=True)
    else:
        rows.append("| read-only / full disk | - | - | - | not measured (needs root to mount a tmpfs) |")
    return rows


def row25(tmp: Path) -> list[str]:
    from tcot_hybrid.learning.checkpoint import checkpoints_dir, stamp_metadata
    from tcot_hybrid.robot import load_robot_spec, robot_model_digest

    rows = ["| checkpoint | run | exit | steps before refusal | message |", "|---|---|---|---|---|"]

    def copy(name: str, edit=None, restamp=False) -> Path:
        d = tmp / name
        d.mkdir()
        src = checkpoints_dir() / "panda_default.safetensors"
        (d / src.name).write_bytes(src.read_bytes())
        meta = json.loads(src.with_suffix(".json").read_text())
        if edit:
            edit(meta)
        (d / "panda_default.json").write_text(json.dumps(stamp_metadata(meta) if restamp else meta))
        return d / src.name

    ur5e = load_robot_spec("ur5e")
    fake = tmp / "fake_panda"
    fake.mkdir()
    (fake / "robot.toml").write_text((ur5e.mjcf_path.parent / "robot.toml").read_text().replace('name = "ur5e"',
                                                                                                'name = "panda"'))
    (fake / "ur5e.xml").write_text(ur5e.mjcf_path.read_text())
    cases = [
        ("shipped, `robot` edited to ur5e", copy("a", lambda m: m.update(robot="ur5e")), "ur5e"),
        ("same, metadata digest recomputed", copy("b", lambda m: m.update(robot="ur5e"), True), "ur5e"),
        ("same + ur5e's model digest", copy("c", lambda m: m.update(robot="ur5e", robot_model_digest=robot_model_digest(ur5e)),
                                             True), "ur5e"),
        ("shipped panda checkpoint", checkpoints_dir() / "panda_default.safetensors", str(fake)),
        ("`windows` as a list", copy("d", lambda m: m.update(windows=[51, 4, 8, 2]), True), "panda"),
        ("vocabulary of ints", copy("e", lambda m: m.update(vocabulary=list(range(31))), True), "panda"),
    ]
    deep = copy("f")
    deep.with_suffix(".json").write_text('{"format": ' + "[" * 200_000 + "]" * 200_000 + "}")
    cases.append(("200k-deep nested metadata", deep, "panda"))
    for label, path, robot in cases:
        out = tmp / f"run_{len(rows)}"
        m = tcot("run", "--task", "goal_cube_on_plate", "--robot", robot, "--planner", "learned", "--checkpoint",
                 str(path), "--out", str(out))
        try:
            steps = json.loads((out / "episode.json").read_text())["steps"]
        except (OSError, KeyError, json.JSONDecodeError):
            steps = "no record"
        who = "a UR5e folder named `panda`" if robot == str(fake) else robot
        msg = clean(m["err"], tmp, 140)
        rows.append(f"| {label} | {who} | {m['rc']} | {steps} | `{msg}` |")
    return rows


def row26(tmp: Path) -> list[str]:
    rows = ["| input | exit | message |", "|---|---|---|"]
    for label, args in (("`--timing.sim-dt/ctrl-dt/plan-dt 1e-300`", ["--timing.sim-dt", "1e-300", "--timing.ctrl-dt",
                                                                        "1e-300", "--timing.plan-dt", "1e-300"]),
                        ("`--timing.sim-dt 0.05`", ["--timing.sim-dt", "0.05", "--timing.ctrl-dt", "0.05"]),
                        ("`--scene.video-width 100000`", ["--scene.video-width", "100000"])):
        m = tcot("run", "--task", "goal_cube_on_plate", *args, "--out", str(tmp / "o26"))
        rows.append(f"| {label} | {m['rc']} | `{clean(m['err'], tmp, 140)}` |")
    panda = ROOT / "robots" / "panda"
    for label, old, new in (("v_max 1e12", "v_max = [2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61]", "v_max = [1e12] "),
                            ("tau_max 1e9 (MJCF ctrlrange matching)", "tau_max = [87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0]",
                             "tau_max = [1e9, 1e9, 1e9, 1e9, 1e9, 1e9, 1e9]")):
        d = tmp / label.split()[0]
        d.mkdir()
        toml = (panda / "robot.toml").read_text().replace('name = "panda"', 'name = "edited"')
        if new.startswith("v_max"):
            new = "v_max = [" + ", ".join(["1e12"] * 7) + "]"
        (d / "robot.toml").write_text(toml.replace(old, new))
        xml = (panda / "panda.xml").read_text()
        if "tau" in label:
            import re

            xml = re.sub(r'(<motor[^>]*ctrlrange=")[^"]*(")', r"\g<1>-1e9 1e9\g<2>", xml)
        (d / "panda.xml").write_text(xml)
        m = tcot("run", "--task", "goal_cube_on_plate", "--robot", str(d), "--out", str(tmp / "o26"))
        rows.append(f"| robot spec {label} | {m['rc']} | `{clean(m['err'], tmp, 140)}` |")
    return rows


def row28(tmp: Path) -> tuple[list[str], dict]:
    from tcot_hybrid.robot_check import check_robot

    short = tmp / "short_panda"
    short.mkdir()
    panda = ROOT / "robots" / "panda"
    (short / "robot.toml").write_text((panda / "robot.toml").read_text().replace('name = "panda"', 'name = "short_panda"'))
    (short / "panda.xml").write_text((panda / "panda.xml").read_text().replace(
        '<body name="link1" pos="0 0 0.333">', '<body name="link1" pos="-0.3 0 0.333">'))
    reports = {}
    for name, ref in (("panda", "panda"), ("ur5e", "ur5e"), ("short_panda", str(short))):
        t0 = time.perf_counter()
        rep = check_robot(ref, seeds=10, png=DOCS / f"reach_{name}.png")
        rep["wall_s"] = round(time.perf_counter() - t0, 1)
        reports[name] = rep
    tasks = [t["task"] for t in reports["panda"]["tasks"]]
    rows = ["| robot | reachable_fraction (workspace) | " + " | ".join(f"`{t}`" for t in tasks) + " | check time [s] |",
            "|---|---|" + "---|" * len(tasks) + "---|"]
    for name, rep in reports.items():
        cells = [f"{t['reachable_fraction']:.2f}" if t["reachable_fraction"] is not None else "-" for t in rep["tasks"]]
        rows.append(f"| {name} | {rep['reachable_fraction']:.3f} | " + " | ".join(cells) + f" | {rep['wall_s']} |")
    # the run on the short arm
    out = tmp / "short_run"
    r = subprocess.run([PY, "-m", "tcot_hybrid.cli", "run", "--robot", str(short), "--task", "object_red_cube_in_basket",
                        "--seed", "3", "--out", str(out)], capture_output=True, text=True, env=ENV, cwd=ROOT, timeout=300)
    rec = json.loads((out / "episode.json").read_text())
    kinds = [e["kind"] for e in rec["events"]]
    run = {"warning": clean(r.stderr.strip().splitlines()[0], tmp, 400) if r.stderr.strip() else "",
           "unreachable_target": kinds.count("unreachable_target"), "unreachable_grasp": kinds.count("unreachable_grasp"),
           "success": rec["success"]}
    return rows, run


def main() -> None:
    from tcot_hybrid.markdown import update_readme_section

    tmp = Path(tempfile.mkdtemp(prefix="tcot-harden-"))
    t0 = time.perf_counter()

    def sub(name: str) -> Path:
        (tmp / name).mkdir()
        return tmp / name

    r23, r24, r25, r26 = row23(sub("23")), row24(sub("24")), row25(sub("25")), row26(sub("26"))
    r28, run = row28(sub("28"))
    text = "\n".join([
        "Measured by `.venv/bin/python docs/reliability/harden.py` (every row through the `tcot` command in a fresh "
        f"process; {time.perf_counter() - t0:.0f} s).",
        "", "#### Row 23: resource bombs (`tcot run --config FILE`)", "", *r23,
        "", "#### Row 24: output locations and records", "", *r24,
        "", "#### Row 25: relabelled or mismatched checkpoints (`tcot run --planner learned --checkpoint FILE`)", "", *r25,
        "", "#### Row 26: absurd timings, sizes and robot specs", "", *r26,
        "", "#### Row 28: reach (`tcot robot check`; task columns: the share of grasp and release points reachable "
        "over seeds 0-9, the lower of the two)", "", *r28, "",
        f"`tcot run --robot short_panda --task object_red_cube_in_basket --seed 3`: before the first step it printed "
        f"`{run['warning']}`; the record holds {run['unreachable_target']} `unreachable_target` and "
        f"{run['unreachable_grasp']} `unreachable_grasp` event(s); success {run['success']}.",
        "", "Reach maps: `docs/reliability/reach_panda.png`, `reach_ur5e.png`, `reach_short_panda.png`.",
    ])
    (DOCS / "harden.md").write_text("# Rows 23-28 figures\n\n" + text + "\n")
    update_readme_section(ROOT / "docs" / "reliability.md", "harden", text)
    shutil.rmtree(tmp, ignore_errors=True)
    print(text)


if __name__ == "__main__":
    main()
