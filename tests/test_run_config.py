import math

import pytest

from tcot_hybrid.config import TimingConfig
from tcot_hybrid.errors import ConfigError
from tcot_hybrid.run_config import RunConfig, load_config_file


def test_timing_whole_multiples():
    t = TimingConfig(sim_dt=0.002, ctrl_dt=0.01, plan_dt=0.1)
    assert (t.substeps, t.ticks_per_plan) == (5, 10)
    with pytest.raises(ConfigError, match="ctrl_dt = 0.003 s must be a whole multiple"):
        TimingConfig(sim_dt=0.002, ctrl_dt=0.003)
    with pytest.raises(ConfigError, match="plan_dt"):
        TimingConfig(plan_dt=0.105)
    with pytest.raises(ConfigError, match="sim_dt must be finite"):
        TimingConfig(sim_dt=math.nan)


def test_yaml_round_trip_and_overrides(tmp_path):
    f = tmp_path / "run.yaml"
    f.write_text("task: goal_open_drawer\nseed: 7\ntiming:\n  ctrl_dt: 0.004\n  sim_dt: 0.002\n")
    cfg = load_config_file(f)
    assert cfg.task == "goal_open_drawer" and cfg.seed == 7 and cfg.timing.ctrl_dt == 0.004
    assert cfg.digest() == load_config_file(f).digest()
    assert cfg.digest() != RunConfig().digest()


@pytest.mark.parametrize("text, fragment", [
    ("sed: 3\n", "unknown key(s) ['sed']"),
    ("seed: three\n", "seed must be an integer"),
    ("timing:\n  sim_dt: .nan\n", "sim_dt must be finite"),
    ("timing:\n  ctrl_dt: -1\n", "ctrl_dt must be > 0"),
    ("timing: 5\n", "timing must be a mapping"),
    ("task: !!python/object/apply:os.system ['echo hi']\n", "malformed"),
    ("task: [unclosed\n", "malformed"),
    ("executor:\n  blend_time_s: -0.1\n", "blend_time_s must be >= 0"),
    ("supervisor:\n  mode: sometimes\n", "supervisor.mode"),
])
def test_malformed_configs_name_the_field(tmp_path, text, fragment):
    f = tmp_path / "bad.yaml"
    f.write_text(text)
    with pytest.raises(ConfigError) as exc:
        load_config_file(f)
    assert fragment in str(exc.value)


def test_unknown_format_and_missing_file(tmp_path):
    with pytest.raises(ConfigError, match="does not exist"):
        load_config_file(tmp_path / "nope.yaml")
    f = tmp_path / "cfg.ini"
    f.write_text("x=1")
    with pytest.raises(ConfigError, match="unknown format"):
        load_config_file(f)
