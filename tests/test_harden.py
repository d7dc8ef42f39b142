"""Hardening round 2 (issue 18; RELIABILITY.md rows 23-28): hostile and careless inputs that used to
crash, hang, eat memory or lose records. Each test failed on the code before the fix."""
from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from tcot_hybrid.config import TIMING_BOUNDS_S, TimingConfig
from tcot_hybrid.errors import ConfigError, short_repr
from tcot_hybrid.run_config import MAX_CONFIG_BYTES, load_config_file

# --- row 23: resource bombs in input files -------------------------------------------------------------

PEAK_RSS_MB = 500
BOMB_SECONDS = 5.0
ERROR_CHARS = 2000


def alias_bomb() -> str:
    """The 422-byte config of issue 18: nine-fold aliases eight deep, 43 million list items expanded."""
    items = ["&a0 [x, x, x, x, x, x, x, x, x]"] + [
        f"&a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, 8)]
    return "task: goal_cube_on_plate\nseed: [" + ", ".join(items) + "]\n"


def bomb_files(tmp: Path) -> dict[str, Path]:
    """Every bomb of the row-23 test set, written to ``tmp``."""
    files = {
        "alias_bomb.yaml": alias_bomb(),
        "alias_bomb_mapping.yaml": "a0: &a0 {x: 1, y: 2}\n" + "".join(
            f"a{i}: &a{i} {{{', '.join(f'k{k}: *a{i - 1}' for k in range(10))}}}\n" for i in range(1, 9)),
        "flat_list_under_limit.yaml": "seed: [" + "1, " * (MAX_CONFIG_BYTES // 3 - 10) + "1]\n",
        "deep.yaml": "seed: " + "[" * 60_000 + "]" * 60_000 + "\n",
        "deep.json": '{"seed": ' + "[" * 100_000 + "]" * 100_000 + "}",
        "deep.toml": "seed = " + "[" * 100_000 + "]" * 100_000 + "\n",
        "long_string.yaml": "seed: " + "x" * (MAX_CONFIG_BYTES - 100) + "\n",
    }
    out = {}
    for name, text in files.items():
        (tmp / name).write_text(text)
        out[name] = tmp / name
    big = tmp / "fifty_mb.yaml"  # issue 18: a 50 MB config with a 25M-item list
    with big.open("w") as f:
        f.write("seed: [")
        chunk = "1, " * 100_000
        for _ in range(167):
            f.write(chunk)
        f.write("1]\n")
    out["fifty_mb.yaml"] = big
    return out


def _measure_load(path: Path) -> dict:
    """Load ``path`` in a fresh interpreter; its own peak RSS, load time, error text."""
    code = textwrap.dedent(f"""
        import json, resource, sys, time
        from tcot_hybrid.run_config import load_config_file
        from tcot_hybrid.errors import TcotError
        t0 = time.perf_counter()
        try:
            load_config_file({str(path)!r})
            err, kind = "", None
        except TcotError as exc:
            err, kind = str(exc), type(exc).__name__
        except BaseException as exc:
            err, kind = repr(exc)[:500], "CRASH:" + type(exc).__name__
        dt = time.perf_counter() - t0
        print(json.dumps({{"s": dt, "rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                          "error": err[:100000], "error_len": len(err), "kind": kind}}))
    """)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    return json.loads(r.stdout)


def test_row23_config_bombs_are_refused_early_with_bounded_memory_time_and_text(tmp_path):
    rows = []
    for name, path in bomb_files(tmp_path).items():
        m = _measure_load(path)
        rows.append((name, path.stat().st_size, m))
        assert m["kind"] == "ConfigError", (name, m)
        assert m["rss_mb"] <= PEAK_RSS_MB, (name, m["rss_mb"])
        assert m["s"] <= BOMB_SECONDS, (name, m["s"])
        assert m["error_len"] <= ERROR_CHARS, (name, m["error_len"])
        assert str(path) in m["error"]
    print("\nrow 23 bombs (file, bytes, peak RSS MB, load s, error chars):")
    for name, size, m in rows:
        print(f"  {name:28s} {size:>10d} {m['rss_mb']:7.0f} {m['s']:6.2f} {m['error_len']:5d}  {m['error'][:90]}")


def test_row23_alias_bomb_through_the_cli_is_short_and_fast(tmp_path):
    f = tmp_path / "bomb.yaml"
    f.write_text(alias_bomb())
    r = subprocess.run([sys.executable, "-m", "tcot_hybrid.cli", "run", "--config", str(f), "--out",
                        str(tmp_path / "o")], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert len(r.stderr) <= ERROR_CHARS and "expands to more than" in r.stderr


def test_short_repr_never_expands_shared_or_deep_values():
    x: list = [1, 2]
    for _ in range(8):
        x = [x] * 9  # 43M leaves, shared
    assert len(short_repr(x)) < 260
    deep: list = []
    for _ in range(100_000):
        deep = [deep]
    assert len(short_repr(deep)) < 260
    assert short_repr([1, "a", {"k": (2, 3)}]) == repr([1, "a", {"k": (2, 3)}])


def test_row23_error_echo_of_a_huge_value_is_bounded():
    with pytest.raises(ConfigError) as exc:
        TimingConfig(sim_dt=[1.0] * 1_000_000)  # type: ignore[arg-type]
    assert len(str(exc.value)) < 400


def test_duplicate_yaml_key_refused(tmp_path):
    f = tmp_path / "dup.yaml"
    f.write_text("seed: 1\ntask: goal_cube_in_bowl\nseed: 2\n")
    with pytest.raises(ConfigError, match=r"key 'seed' appears twice \(line 1 and line 3\)"):
        load_config_file(f)
    f.write_text("timing:\n  sim_dt: 0.002\n  sim_dt: 0.001\n")
    with pytest.raises(ConfigError, match="sim_dt' appears twice"):
        load_config_file(f)
    f.write_text("a: &x {seed: 1}\n")  # an anchor alone is fine syntax (then an unknown key)
    with pytest.raises(ConfigError, match="unknown key"):
        load_config_file(f)


def test_config_path_that_is_a_directory_or_device_is_named_as_such(tmp_path):
    with pytest.raises(ConfigError, match="is a directory"):
        load_config_file(tmp_path)
    with pytest.raises(ConfigError, match="not a regular file"):
        load_config_file("/dev/zero")
    with pytest.raises(ConfigError, match="does not exist"):
        load_config_file(tmp_path / "nope.yaml")


# --- row 26: physically absurd timings ----------------------------------------------------------------

@pytest.mark.parametrize("field", ["sim_dt", "ctrl_dt", "plan_dt"])
@pytest.mark.parametrize("value", [1e-300, 1e-7, 5.0, 1e6])
def test_row26_time_steps_out_of_range_refused_with_the_bound(field, value):
    kw = {"sim_dt": value, "ctrl_dt": value, "plan_dt": value}
    lo, hi = TIMING_BOUNDS_S["sim_dt"]
    with pytest.raises(ConfigError) as exc:
        TimingConfig(**kw)
    msg = str(exc.value)
    assert "sim_dt" in msg and f"[{lo:g}, {hi:g}]" in msg
    base = {"sim_dt": 0.002, "ctrl_dt": 0.01, "plan_dt": 0.1}
    base[field] = value
    lo, hi = TIMING_BOUNDS_S[field]
    with pytest.raises(ConfigError, match=field):
        TimingConfig(**base)


def test_row26_time_step_bounds_keep_the_defaults_and_the_tested_settings():
    TimingConfig()
    TimingConfig(sim_dt=0.001, ctrl_dt=0.002, plan_dt=0.1)
    TimingConfig(sim_dt=0.002, ctrl_dt=0.004, plan_dt=0.2)
