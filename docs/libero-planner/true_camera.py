"""The learned planner under `camera_shift` lifting with the moved camera itself, known exactly: what a perfect
calibration would give, beside the self-calibration's estimate (self_calibration.py; docs/libero-planner.md, "A
knocked camera"). The moved camera is read from MuJoCo the moment the perturbation fires and handed to the planner's
calibration in place of any estimate; nothing else changes. Sampled development layouts 20000-20001 (docs/seeds.md),
GLSR, the shipped four-suite checkpoint; resumable (episodes already in the output are skipped):

    .venv/bin/python docs/libero-planner/true_camera.py --part 0 --parts 2 &   # one process per core
    .venv/bin/python docs/libero-planner/true_camera.py --part 1 --parts 2
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import dev_runs  # this folder's: run as a script, the folder is on sys.path
from tcot_hybrid import calibration, perturbations
from tcot_hybrid.camera import CameraModel
from tcot_hybrid.episode import EpisodeRunner
from tcot_hybrid.perturbations import PerturbConfig
from tcot_hybrid.run_config import RunConfig
from tcot_hybrid.supervision import SupervisorConfig
from tcot_hybrid.tasks.registry import suite_task_names

ROOT = Path(__file__).resolve().parent.parent.parent
OUT = ROOT / "runs" / "dev" / "true_camera" / "episodes.jsonl"
CHECKPOINT = "tcot_hybrid/checkpoints/libero_panda_default.safetensors"
_fire = perturbations.CameraShift.fire
_add = calibration.CameraSelfCalibration.add


def fire_and_tell(self, runner, step):
    """CameraShift.fire, then the planner's calibration is set to the moved camera and kept there."""
    event = _fire(self, runner, step)
    s = runner.stack
    cal = s.planner.calibration
    cal.camera = CameraModel.from_mujoco(s.sim.model, s.sim.data, runner.cfg.scene.planner_camera,
                                         width=s.camera.width, height=s.camera.height)
    cal.known_exactly = True
    return event


def add_unless_known(self, *args):
    return self.camera if getattr(self, "known_exactly", False) else _add(self, *args)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--part", type=int, default=0)
    ap.add_argument("--parts", type=int, default=1)
    args = ap.parse_args()
    perturbations.CameraShift.fire = fire_and_tell
    calibration.CameraSelfCalibration.add = add_unless_known
    OUT.parent.mkdir(parents=True, exist_ok=True)
    done = {(r["task"], r["seed"]) for r in map(json.loads, OUT.read_text().splitlines())} if OUT.is_file() else set()
    tasks = [t for s in dev_runs.SUITES for t in suite_task_names(s)]
    for i, task in enumerate(tasks):
        if i % args.parts != args.part:
            continue
        for seed in (20000, 20001):
            if (task, seed) in done:
                continue
            cfg = RunConfig(task=task, seed=seed, init="sampled", planner="learned", checkpoint=CHECKPOINT,
                            supervisor=SupervisorConfig(mode="glsr"), perturb=PerturbConfig(name="camera_shift"))
            r = EpisodeRunner(cfg).run()
            with OUT.open("a") as f:  # one line per episode, appended at once: the parts share the file
                f.write(json.dumps({"task": task, "suite": r["suite"], "mode": "glsr", "seed": seed,
                                    "perturb": "camera_shift", "success": r["success"],
                                    "perturbation_fired": r["perturbation_fired"]}) + "\n")


if __name__ == "__main__":
    main()
