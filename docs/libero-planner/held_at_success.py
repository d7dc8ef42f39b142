"""How LIBERO demonstrations end (docs/libero-planner.md, "What is left"): per suite, the share of successful demos
whose first success frame has the gripper closed (LIBERO's `In`/`On` hold while the object is still in the hand) and
whose last frame still has it closed (collection stops a few steps after success, before the script's release):

    .venv/bin/python docs/libero-planner/held_at_success.py [--data data/demos_libero_panda.hdf5]
"""
from __future__ import annotations

import argparse
from collections import defaultdict

import numpy as np

from tcot_hybrid.data.dataset import open_demos


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default="data/demos_libero_panda.hdf5")
    a = ap.parse_args()
    rows = defaultdict(list)
    with open_demos(a.data) as f:
        for info in f.infos():
            if not info.success or info.t_success < 0:
                continue
            closed = f.read(info.name, ("obs/robot0_gripper_closed",))["obs/robot0_gripper_closed"] > 0.5
            rows[info.suite].append(
                (bool(closed[info.t_success]), bool(closed[-1]), len(closed) - info.t_success))
    print("| suite | successful demos | closed at first success | closed at the end | frames after success (median) |")
    print("|---|---|---|---|---|")
    for suite, v in sorted(rows.items()):
        x = np.array(v, dtype=float)
        print(f"| {suite} | {len(v)} | {x[:, 0].mean():.2f} | {x[:, 1].mean():.2f} | {np.median(x[:, 2]):.0f} |")


if __name__ == "__main__":
    main()
