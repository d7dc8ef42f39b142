"""One LIBERO episode's goal, traced: every ``--every`` planner steps the hand, the gripper command, and the world
position of each object the task's goal predicates name with the bodies it touches, and the joints of any articulated
fixture whose region they name; at the end each goal predicate's truth. A diagnostic for
docs/libero-planner.md ("The bottom drawer: a bowl carried out again"); nothing is saved.

    MUJOCO_GL=egl .venv/bin/python docs/libero-planner/goal_trace.py --task TASK --seed 20026 [--planner oracle]
"""
from __future__ import annotations

import argparse

import numpy as np

import dev_runs  # this folder's: run as a script, the folder is on sys.path


def main() -> None:
    from tcot_hybrid.episode import EpisodeRunner
    from tcot_hybrid.workers import one_torch_thread

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--task", required=True)
    ap.add_argument("--seed", type=int, required=True)
    ap.add_argument("--planner", default="learned", choices=("learned", "oracle"))
    ap.add_argument("--mode", default="global", choices=("global", "glsr"))
    ap.add_argument("--checkpoint", help="the learned planner's checkpoint (default: the task's shipped model)")
    ap.add_argument("--every", type=int, default=5, help="planner steps between rows")
    ap.add_argument("--since", type=int, default=0, help="first planner step traced")
    ap.add_argument("--until", type=int, default=200, help="last planner step traced")
    a = ap.parse_args()
    runner = EpisodeRunner(dev_runs.episode_config(a.task, a.seed, a.planner, a.mode, a.checkpoint))
    scene = runner.stack.task.scene
    env, m = scene.env, scene.model
    goals = env.parsed_problem["goal_state"]
    names = sorted({n for g in goals for n in g[1:] if n in env.objects_dict})
    bodies = {n: m.body(env.objects_dict[n].root_body).id for n in names}
    # a goal on a region of an articulated fixture (a drawer, a door, a knob): that fixture's joints
    parents = {getattr(env.object_states_dict.get(n), "parent_name", None) for g in goals for n in g[1:]
               if n not in env.objects_dict}
    joints = {m.joint(j).name: int(m.jnt_qposadr[j]) for j in range(m.njnt)
              if any(p in env.fixtures_dict and (m.joint(j).name or "").startswith(p + "_") for p in parents)}
    columns = (["step", "hand [m]", "gripper"] + [f"{n} [m], touching" for n in names]
               + ["joints [m or rad]"] * bool(joints))
    print("| " + " | ".join(columns) + " |")
    print("|" + "---|" * len(columns))

    def touching(d, body: int) -> str:
        root = m.body_rootid[body]
        other = set()
        for c in d.contact[:d.ncon]:
            b1, b2 = m.geom_bodyid[c.geom1], m.geom_bodyid[c.geom2]
            if m.body_rootid[b1] == root and m.body_rootid[b2] != root:
                other.add(m.body(b2).name)
            elif m.body_rootid[b2] == root and m.body_rootid[b1] != root:
                other.add(m.body(b1).name)
        return ", ".join(sorted(other)) or "-"

    def row(r, step):
        if step % a.every or not a.since <= step <= a.until:
            return
        sim = r.stack.sim
        cells = [str(step), np.array2string(sim.tcp_pos(), precision=3),
                 "closed" if sim.gripper_closed_cmd() else "open"]
        cells += [f"{np.array2string(sim.data.xpos[bodies[n]], precision=3)}, {touching(sim.data, bodies[n])}"
                  for n in names]
        cells += [", ".join(f"{n} {sim.data.qpos[adr]:.3f}" for n, adr in joints.items())] * bool(joints)
        print("| " + " | ".join(cells) + " |")

    runner.frame_hook = row
    with one_torch_thread():  # as `tcot run` and the evaluation's workers: an episode can turn on the last bits
        runner.run()
    print(f"\nsuccess: {runner.success} after {runner.steps} steps")
    for g in goals:
        print(f"- `{' '.join(g)}`: {bool(env._eval_predicate(g))}")


if __name__ == "__main__":
    main()
