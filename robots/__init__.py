"""Bundled robots: one folder per robot with an MJCF file and a robot.toml (docs/robot_spec.md).

Installed as ``tcot_hybrid.robots``; load them with ``tcot_hybrid.robot.load_robot_spec(name)``.
"""
