"""Evaluation reports as Markdown: every cell, the paper's Table 1 and Table 4 forms, IK backends side by side,
detector figures."""
from __future__ import annotations

import math
from collections import defaultdict


def _rate(group: list[dict]) -> tuple[float, float, int]:
    k = sum(c["successes"] for c in group)
    n = sum(c["episodes"] for c in group)
    p = k / n if n else 0.0
    return p, math.sqrt(p * (1 - p) / n) if n else 0.0, n


def ik_table(cells: list[dict]) -> list[str]:
    """Markdown lines comparing IK backends (only when an evaluation ran more than one): per robot and backend,
    success, mean episode time, mean of the episodes' largest tracking error, IK failures, worst limit violation."""
    if len({c["ik"] for c in cells}) < 2:
        return []
    groups: dict[tuple, list] = defaultdict(list)
    for c in cells:
        groups[(c["robot"], c["ik"])].append(c)
    lines = ["", "#### IK backends", "",
             "| robot | ik | success ± s.e. | n | mean episode time [s] | mean tracking error [rad] | "
             "waypoints not converged | plans infeasible | max limit viol. [rad] |",
             "|---|---|---|---|---|---|---|---|---|"]
    for (robot, ik), group in sorted(groups.items()):
        p, se, n = _rate(group)

        def weighted(key):
            pairs = [(c[key], c["episodes"]) for c in group if c.get(key) is not None]
            return round(sum(v * w for v, w in pairs) / sum(w for _, w in pairs), 4) if pairs else None

        lines.append(f"| {robot} | {ik} | {p:.3f} ± {se:.3f} | {n} | {weighted('mean_episode_time_s')} | "
                     f"{weighted('mean_tracking_error_rad')} | {sum(c.get('ik_not_converged', 0) for c in group)} | "
                     f"{sum(c.get('plans_infeasible', 0) for c in group)} | "
                     f"{max(c['max_joint_limit_violation_rad'] for c in group):.1e} |")
    return lines


def markdown(result: dict, *, with_cells: bool = True) -> str:
    """The evaluation as Markdown: every cell (optional), Table 1 and Table 4 forms, detector metrics."""
    cells = result["cells"]
    lines = [] if not with_cells else ["## Cells", "",
             "| task | planner | mode | perturb | robot | controller | ik | sweep | success ± s.e. | n | "
             "mean time [s] | replans | max limit viol. [rad] | max \\|q̇\\|/v_max |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for c in cells if with_cells else ():
        lines.append(f"| {c['task']} | {c['planner']} | {c['mode']} | {c['perturb']} | {c['robot']} | "
                     f"{c['controller']} | {c['ik']} | {c['sweep']} | {c['success_rate']:.2f} ± {c['stderr']:.2f} | "
                     f"{c['episodes']} | {c['mean_episode_time_s']} | {c['mean_replans']} | "
                     f"{c['max_joint_limit_violation_rad']:.1e} | {c['max_velocity_ratio']:.2f} |")
    n_ep = sum(c["episodes"] for c in cells)
    lines += ["", f"Over all {n_ep} episodes: max joint-limit violation "
              f"{max(c['max_joint_limit_violation_rad'] for c in cells):.2e} rad, max |q̇|/v_max "
              f"{max(c['max_velocity_ratio'] for c in cells):.3f}, sim faults {sum(c['faults'] for c in cells)}."]
    # Table 1: per suite success ± s.e. for each configuration row.
    suites = sorted({c["suite"] for c in cells})
    rows: dict[tuple, dict[str, list]] = defaultdict(lambda: defaultdict(list))
    for c in cells:
        rows[(c["planner"], c["mode"], c["perturb"], c["robot"], c["controller"], c["ik"], c["sweep"])][c["suite"]].append(c)
    lines += ["", "#### Table 1 form: success per suite (± standard error)", "",
              "| planner | mode | perturb | robot | controller | ik | sweep | " + " | ".join(suites) + " | avg |",
              "|" + "---|" * (8 + len(suites))]
    for key, by_suite in sorted(rows.items()):
        vals = [_rate(by_suite[s]) if by_suite.get(s) else None for s in suites]
        avg = _rate([c for s in suites for c in by_suite.get(s, [])])
        lines.append("| " + " | ".join(key) + " | " + " | ".join(
            f"{v[0]:.3f} ± {v[1]:.3f}" if v else "–" for v in vals) + f" | {avg[0]:.3f} ± {avg[1]:.3f} |")
    lines += ik_table(cells)
    # Table 4: ablation of planning modes (averaged over suites), per perturbation.
    abl: dict[tuple, list] = defaultdict(list)
    for c in cells:
        label = "direct (no trajectory)" if c["planner"] == "direct" else (
            f"oracle ({c['mode']})" if c["planner"] == "oracle" else c["mode"])
        abl[(c["perturb"], label)].append(c)
    lines += ["", "#### Table 4 form: ablation (average over suites)", "",
              "| perturbation | method | success ± s.e. | n |", "|---|---|---|---|"]
    for (pert, label), group in sorted(abl.items()):
        p, se, n = _rate(group)
        lines.append(f"| {pert} | {label} | {p:.3f} ± {se:.3f} | {n} |")
    det = result.get("detector") or {}
    if det:
        lines += ["", "#### Failure detector", "", "| planner | calls | AUROC | false-alarm rate | latency [steps] |",
                  "|---|---|---|---|---|"]
        for planner, d in det.items():
            lines.append(f"| {planner} | {d['calls']} | {d['auroc']} | {d['false_alarm_rate']} | "
                         f"{d['detection_latency_steps']} |")
    return "\n".join(lines) + "\n"
