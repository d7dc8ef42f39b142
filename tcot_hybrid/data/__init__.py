"""Demonstration data: collection (``tcot collect``), the HDF5 reader, trajectory labels (paper eq. 4/5)
and the calibration-free vision label path (``tcot labels``)."""
import os

os.environ.setdefault("MUJOCO_GL", "egl")  # spawned collection workers import this package first

from tcot_hybrid.data.dataset import DemoFile, DemoInfo, open_demos  # noqa: E402

__all__ = ["DemoFile", "DemoInfo", "open_demos"]
