"""Markdown writers for the docs: sections of README.md (and docs/*.md) rewritten by the commands that
measure their figures, and the ``tcot bench`` table."""
from __future__ import annotations

from pathlib import Path


def bench_markdown(result: dict) -> str:
    """``tcot bench``'s result (bench.json) as Markdown: the command, figures and ratios."""
    lines = [f"Measured by `{result['command']}` (robot {result['robot']}, task {result['task']}, "
             f"sim_dt {result['timing']['sim_dt']} s, ctrl_dt {result['timing']['ctrl_dt']} s, "
             f"plan_dt {result['timing']['plan_dt']} s, {result['machine']['cpus']} CPUs).", "",
             "| figure | median | min | max | unit |", "|---|---|---|---|---|"]
    for name, f in result["figures"].items():
        lines.append(f"| {name} | {f['median']:.4g} | {f['min']:.4g} | {f['max']:.4g} | {f['unit']} |")
    lines += ["", "| ratio | value |", "|---|---|"]
    lines += [f"| {k} | {v:.4g} |" for k, v in result["ratios"].items()]
    lines += [f"\nNote: {n}" for n in result.get("notes", [])]
    return "\n".join(lines) + "\n"


def _section_markers(marker: str) -> tuple[str, str]:
    return f"<!-- {marker}:start -->", f"<!-- {marker}:end -->"


def has_readme_section(readme: str | Path, marker: str) -> bool:
    """Whether the Markdown file exists and has a <!-- {marker}:start/end --> section."""
    p = Path(readme)
    if not p.is_file():
        return False
    s = p.read_text()
    return all(m in s for m in _section_markers(marker))


def update_readme_section(readme: str | Path, marker: str, text: str, *, inside: str | None = None) -> None:
    """Replace the text between <!-- {marker}:start --> and <!-- {marker}:end --> in the README. With
    ``inside``, a missing section is first created just before <!-- {inside}:end -->."""
    p = Path(readme)
    s = p.read_text()
    start, end = _section_markers(marker)
    if (start not in s or end not in s) and inside is not None and f"<!-- {inside}:end -->" in s:
        s = s.replace(f"<!-- {inside}:end -->", f"{start}\n{end}\n<!-- {inside}:end -->", 1)
    if start not in s or end not in s:
        raise ValueError(f"{p} has no {start} … {end} section")
    head, rest = s.split(start, 1)
    _, tail = rest.split(end, 1)
    p.write_text(f"{head}{start}\n{text.rstrip()}\n{end}{tail}")
