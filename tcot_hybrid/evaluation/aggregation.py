"""Aggregating episode records: cells (success rate and interval per configuration) and failure-detector
figures."""
from __future__ import annotations

import math
from collections import defaultdict

from tcot_hybrid.evaluation.jobs import CELL_KEYS
from tcot_hybrid.metrics import auroc, wilson_interval


def _mean(xs):
    xs = [x for x in xs if x is not None]
    return round(sum(xs) / len(xs), 4) if xs else None


def aggregate(records: list[dict]) -> list[dict]:
    """One cell per configuration: successes of n with the Wilson 95 % interval (``ci95``), the normal-approximation
    standard error (``stderr``, kept for older readers), faults, timing, perturbation and stopping figures.

    perturbation_fired: episodes in which the cell's perturbation fired (None for ``perturb = none``); a cell
        where it never fired measures the unperturbed task, and ``perturbation_notes`` says why.
    premature_stops: detector-stopped episodes (``stop_on = detector``) the success predicate did not confirm.
    """
    groups: dict[tuple, list[dict]] = defaultdict(list)
    for r in records:
        groups[tuple(r.get(k, "-" if k == "sweep" else "none") for k in CELL_KEYS)].append(r)
    cells = []
    for key, recs in groups.items():
        n = len(recs)
        k = sum(bool(r["success"]) for r in recs)
        p = k / n
        lo, hi = wilson_interval(k, n)
        cell = dict(zip(CELL_KEYS, key))
        perturbed = cell["perturb"] != "none"
        cell.update(episodes=n, successes=k, success_rate=round(p, 4), ci95=[round(lo, 4), round(hi, 4)],
                    stderr=round(math.sqrt(p * (1 - p) / n), 4),
                    faults=sum(bool(r.get("fault")) for r in recs),
                    perturbation_fired=sum(bool(r.get("perturbation_fired")) for r in recs) if perturbed else None,
                    perturbation_notes=sorted({r["perturbation_note"] for r in recs if r.get("perturbation_note")})
                    if perturbed else [],
                    stop_on=sorted({r.get("stop_on", "simulator") for r in recs})[0],
                    premature_stops=sum(bool(r.get("premature_stop")) for r in recs),
                    mean_episode_time_s=_mean([r.get("success_time_s") or r.get("sim_time_s") for r in recs]),
                    mean_wall_time_s=_mean([r.get("wall_time_s") for r in recs]),
                    mean_replans=_mean([r.get("replans") for r in recs]),
                    mean_tracking_error_rad=_mean([r.get("max_tracking_error_rad") for r in recs]),
                    max_joint_limit_violation_rad=max(r.get("max_joint_limit_violation_rad", 0.0) for r in recs),
                    max_velocity_ratio=round(max(r.get("max_velocity_ratio", 0.0) for r in recs), 4),
                    ik_not_converged=sum(int(r.get("ik_failures") or 0) for r in recs),
                    plans_infeasible=sum(int(r.get("plans_infeasible") or 0) for r in recs),
                    failed_seeds=sorted(r["seed"] for r in recs if not r["success"]))
        cells.append(cell)
    return cells


def detector_metrics(records: list[dict], threshold: float = 0.5) -> dict:
    """Failure-detector figures per planner from the logged (p_success, ground truth) pairs.

    in_episode_auroc: over the frames the detector judged while the episode ran (GLSR's detection steps and,
        with ``stop_on = detector``, every stop check; one frame per step), before and after true success. Under
        simulator stopping an episode ends at its first success frame, so these are nearly all negatives and the
        figure is usually None.
    auroc: over the in-episode frames plus the probes after a simulator-judged success (``detector`` events).
    false_alarm_rate: fraction of successful episodes in which the detector judged the finished task
        not successful (p < threshold) on any post-success probe, i.e. would have replanned needlessly.
    detection_latency_steps: planner steps from true success to the detector's first p >= threshold (probes).
    """
    by_planner: dict[str, dict] = defaultdict(lambda: {"scores": [], "labels": [], "ep_scores": [], "ep_labels": [],
                                                       "alarms": 0, "successes": 0, "latency": []})
    for r in records:
        events = [e for e in r.get("events", []) if "p_success" in e]
        in_episode: dict[int, tuple[float, bool]] = {}
        for kind in ("supervisor", "stop_check"):  # the same step's frame once, whoever asked
            for e in events:
                if e.get("kind") == kind:
                    in_episode.setdefault(e.get("step"), (e["p_success"], bool(e.get("true_success"))))
        post = [e for e in events if e.get("kind") == "detector"]
        if not in_episode and not post:
            continue
        d = by_planner[r["planner"]]
        for p, y in list(in_episode.values()) + [(e["p_success"], bool(e.get("true_success"))) for e in post]:
            d["scores"].append(p)
            d["labels"].append(y)
        for p, y in in_episode.values():
            d["ep_scores"].append(p)
            d["ep_labels"].append(y)
        if r.get("success") and post:
            d["successes"] += 1
            d["alarms"] += any(e["p_success"] < threshold for e in post)
            hits = [i for i, e in enumerate(post) if e["p_success"] >= threshold]
            if hits:
                d["latency"].append(hits[0])
    out = {}
    for planner, d in by_planner.items():
        a, a_ep = auroc(d["scores"], d["labels"]), auroc(d["ep_scores"], d["ep_labels"])
        out[planner] = {"calls": len(d["scores"]), "positives": sum(d["labels"]),
                        "auroc": None if a is None else round(a, 4),
                        "in_episode_frames": len(d["ep_scores"]), "in_episode_positives": sum(d["ep_labels"]),
                        "in_episode_auroc": None if a_ep is None else round(a_ep, 4),
                        "false_alarm_rate": round(d["alarms"] / d["successes"], 4) if d["successes"] else None,
                        "successful_episodes_probed": d["successes"],
                        "detection_latency_steps": _mean(d["latency"])}
    return out
