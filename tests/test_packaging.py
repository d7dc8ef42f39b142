"""The source tree and an installed wheel import the same way: a process started in the checkout root (``python
-c``, ``tcot bench``'s subprocesses) imports the source tree, which must hold tcot_hybrid.controllers and
tcot_hybrid.robots as the wheel does."""
import subprocess
import sys
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_source_tree_imports_like_the_installed_package():
    code = ("import tcot_hybrid, tcot_hybrid.controllers, tcot_hybrid.robots; "
            "from tcot_hybrid.controllers import list_controllers; from tcot_hybrid.robot import list_robots; "
            "print(tcot_hybrid.__file__); print(list_controllers()); print(list_robots())")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-800:]
    file, ctrls, robots = out.stdout.strip().splitlines()
    assert Path(file).resolve().is_relative_to(ROOT)  # the source tree, not site-packages
    assert "computed_torque" in ctrls and "panda" in robots


def test_wheel_holds_every_package_and_the_robot_files(tmp_path):
    out = subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation", str(ROOT),
                          "-w", str(tmp_path)], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-800:]
    (wheel,) = tmp_path.glob("*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    source_packages = {p.parent.relative_to(ROOT).as_posix() for p in (ROOT / "tcot_hybrid").rglob("__init__.py")
                       if "__pycache__" not in p.parts}
    for pkg in source_packages:
        assert f"{pkg}/__init__.py" in names, pkg
    for spec in (ROOT / "robots").glob("*/robot.toml"):
        assert f"tcot_hybrid/robots/{spec.parent.name}/robot.toml" in names
    assert "tcot_hybrid/controllers/computed_torque.py" in names
    assert "tcot_hybrid/checkpoints/panda_default.safetensors" in names
