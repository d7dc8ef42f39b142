"""Evaluation reports as Markdown: every cell, the paper's Table 1 and Table 4 forms, detector figures."""
from __future__ import annotations

import math
from collections import defaultdict


def _rate(group: list[dict]) -> tuple[float, float, int]:
    k = sum(c["successes"] for c in group)
    n = sum(c["episodes"] for c in group)
    p = k / n if n else 0.0
    return p, math.sqrt(p * (1 - p) / n) if n else 0.0, n


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
