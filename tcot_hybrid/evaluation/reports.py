"""Evaluation reports as Markdown: every cell, the paper's Table 1 and Table 4 forms, IK backends side by side,
detector figures.

Success is written as the rate with its Wilson 95 % interval and n (``0.90 [0.60, 0.98] n=10``): at the
n of these tables a normal-approximation ``± s.e.`` collapses to ``± 0.00`` at 0/n and n/n. A perturbed
cell in which the perturbation never fired is written ``not fired (n=…)`` instead of a rate and left out of
the averages (it measured the unperturbed task): an average's n counts only cells where it fired. The
``fired`` column says in how many of all the perturbed episodes it fired.
"""
from __future__ import annotations

from collections import defaultdict

from tcot_hybrid.metrics import wilson_interval


class Rate:
    """Pooled successes of a group of cells. Cells whose perturbation never fired are left out of the rate (they
    measured the unperturbed task); ``fired`` still counts over every perturbed episode of the group."""

    def __init__(self, group: list[dict]):
        perturbed = [c for c in group if c.get("perturb", "none") != "none"]
        self.perturbed_n = sum(c["episodes"] for c in perturbed)
        self.fired = sum(c.get("perturbation_fired") or 0 for c in perturbed)
        self.premature = sum(c.get("premature_stops") or 0 for c in group)
        counted = [c for c in group if c.get("perturb", "none") == "none" or c.get("perturbation_fired") != 0]
        self.k = sum(c["successes"] for c in counted)
        self.n = sum(c["episodes"] for c in counted)
        self.p = self.k / self.n if self.n else 0.0
        self.lo, self.hi = wilson_interval(self.k, self.n)
        self.total_n = sum(c["episodes"] for c in group)

    @property
    def never_fired(self) -> bool:
        return self.perturbed_n > 0 and self.fired == 0

    def text(self, digits: int = 2) -> str:
        if self.never_fired:
            return f"not fired (n={self.total_n})"
        return f"{self.p:.{digits}f} [{self.lo:.{digits}f}, {self.hi:.{digits}f}] n={self.n}"

    def fired_text(self) -> str:
        return "-" if not self.perturbed_n else f"{self.fired}/{self.perturbed_n}"


def perturbation_notes(cells: list[dict]) -> list[str]:
    """One line per (perturbation, task) whose perturbation did not fire in every episode: how often it fired
    and the reasons recorded (e.g. the task has no target receptacle, at_step after the episode's end)."""
    groups: dict[tuple, list[dict]] = defaultdict(list)
    for c in cells:
        if c.get("perturbation_fired") is not None:
            groups[(c["perturb"], c["task"])].append(c)
    lines = []
    for (pert, task), group in sorted(groups.items()):
        fired, n = sum(c["perturbation_fired"] for c in group), sum(c["episodes"] for c in group)
        if fired < n:
            why = "; ".join(sorted({note for c in group for note in c.get("perturbation_notes") or []}))
            lines.append(f"- `{pert}` on `{task}`: fired in {fired} of {n} episodes" + (f" ({why})" if why else ""))
    return lines


def ik_table(cells: list[dict]) -> list[str]:
    """Markdown lines comparing IK backends (only when an evaluation ran more than one): per robot and backend,
    success, mean episode time, mean of the episodes' largest tracking error, IK failures, worst limit violation."""
    if len({c["ik"] for c in cells}) < 2:
        return []
    groups: dict[tuple, list] = defaultdict(list)
    for c in cells:
        groups[(c["robot"], c["ik"])].append(c)
    lines = ["", "#### IK backends", "",
             "| robot | ik | success [Wilson 95 % interval] n | mean episode time [s] | mean tracking error [rad] | "
             "waypoints not converged | plans infeasible | max limit viol. [rad] |",
             "|---|---|---|---|---|---|---|---|"]
    for (robot, ik), group in sorted(groups.items()):
        def weighted(key):
            pairs = [(c[key], c["episodes"]) for c in group if c.get(key) is not None]
            return round(sum(v * w for v, w in pairs) / sum(w for _, w in pairs), 4) if pairs else None

        lines.append(f"| {robot} | {ik} | {Rate(group).text(3)} | {weighted('mean_episode_time_s')} | "
                     f"{weighted('mean_tracking_error_rad')} | {sum(c.get('ik_not_converged', 0) for c in group)} | "
                     f"{sum(c.get('plans_infeasible', 0) for c in group)} | "
                     f"{max(c['max_joint_limit_violation_rad'] for c in group):.1e} |")
    return lines


def markdown(result: dict, *, with_cells: bool = True) -> str:
    """The evaluation as Markdown: every cell (optional), Table 1 and Table 4 forms, detector metrics."""
    cells = result["cells"]
    detector_stopped = any(c.get("stop_on") in ("detector", "either") for c in cells)
    lines = [] if not with_cells else ["## Cells", "",
             "| task | planner | mode | perturb | robot | controller | ik | sweep | success [95 % CI] n | fired | "
             "premature stops | mean time [s] | replans | max limit viol. [rad] | max \\|q̇\\|/v_max |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for c in cells if with_cells else ():
        r = Rate([c])
        lines.append(f"| {c['task']} | {c['planner']} | {c['mode']} | {c['perturb']} | {c['robot']} | "
                     f"{c['controller']} | {c['ik']} | {c['sweep']} | {r.text()} | {r.fired_text()} | "
                     f"{c.get('premature_stops', 0)} | {c['mean_episode_time_s']} | {c['mean_replans']} | "
                     f"{c['max_joint_limit_violation_rad']:.1e} | {c['max_velocity_ratio']:.2f} |")
    n_ep = sum(c["episodes"] for c in cells)
    lines += ["", f"Over all {n_ep} episodes: max joint-limit violation "
              f"{max(c['max_joint_limit_violation_rad'] for c in cells):.2e} rad, max |q̇|/v_max "
              f"{max(c['max_velocity_ratio'] for c in cells):.3f}, sim faults {sum(c['faults'] for c in cells)}."
              + (f" Episodes ended by the failure detector (`--stop-on "
                 f"{'/'.join(sorted({c.get('stop_on') for c in cells} & {'detector', 'either'}))}`); premature stops "
                 f"(stopped, predicate false): {sum(c.get('premature_stops', 0) for c in cells)} of {n_ep}."
                 if detector_stopped else "")]
    # Table 1: per suite success for each configuration row.
    suites = sorted({c["suite"] for c in cells})
    rows: dict[tuple, dict[str, list]] = defaultdict(lambda: defaultdict(list))
    for c in cells:
        rows[(c["planner"], c["mode"], c["perturb"], c["robot"], c["controller"], c["ik"], c["sweep"])][c["suite"]].append(c)
    lines += ["", "#### Table 1 form: success per suite [Wilson 95 % interval] n", "",
              "| planner | mode | perturb | robot | controller | ik | sweep | " + " | ".join(suites) + " | avg | fired |",
              "|" + "---|" * (9 + len(suites))]
    for key, by_suite in sorted(rows.items()):
        vals = [Rate(by_suite[s]).text() if by_suite.get(s) else "–" for s in suites]
        avg = Rate([c for s in suites for c in by_suite.get(s, [])])
        lines.append("| " + " | ".join(key) + " | " + " | ".join(vals) + f" | {avg.text(3)} | {avg.fired_text()} |")
    lines += ik_table(cells)
    # Table 4: ablation of planning modes (averaged over suites), per perturbation.
    abl: dict[tuple, list] = defaultdict(list)
    for c in cells:
        label = "direct (no trajectory)" if c["planner"] == "direct" else (
            f"oracle ({c['mode']})" if c["planner"] == "oracle" else c["mode"])
        abl[(c["perturb"], label)].append(c)
    lines += ["", "#### Table 4 form: ablation (average over suites)", "",
              "| perturbation | method | success | 95 % CI | n | fired |"
              + (" premature stops |" if detector_stopped else ""),
              "|---|---|---|---|---|---|" + ("---|" if detector_stopped else "")]
    for (pert, label), group in sorted(abl.items()):
        r = Rate(group)
        rate = "not fired" if r.never_fired else f"{r.p:.3f}"
        lines.append(f"| {pert} | {label} | {rate} | [{r.lo:.3f}, {r.hi:.3f}] | {r.n} | {r.fired_text()} |"
                     + (f" {r.premature} |" if detector_stopped else ""))
    notes = perturbation_notes(cells)
    if notes:
        lines += ["", "Perturbations that did not fire in every episode of a cell, and why:", "", *notes]
    det = result.get("detector") or {}
    if det:
        lines += ["", "#### Failure detector", "",
                  "| planner | frames (positives) | AUROC with post-success probes | in-episode frames (positives) | "
                  "in-episode AUROC | false-alarm rate | latency [steps] |", "|---|---|---|---|---|---|---|"]
        for planner, d in det.items():
            lines.append(f"| {planner} | {d['calls']} ({d['positives']}) | {d['auroc']} | "
                         f"{d.get('in_episode_frames', '–')} ({d.get('in_episode_positives', '–')}) | "
                         f"{d.get('in_episode_auroc')} | {d['false_alarm_rate']} | {d['detection_latency_steps']} |")
    return "\n".join(lines) + "\n"
