"""Success predicates, positive and negative, on real simulator states.

Every predicate is checked on a state where it must hold (released, settled, upright, in place) and on the
states that must not count: the object still clamped in closed fingers over or in the target, resting on a
rim, tipped over, still moving, just outside the footprint. The arm is placed kinematically (IK solution
written into qpos every physics step) so the fingers can clamp an object exactly where a delivery ends.
"""
import os

os.environ.setdefault("MUJOCO_GL", "egl")

import mujoco
import numpy as np
import pytest

from tcot_hybrid.config import TimingConfig
from tcot_hybrid.ik import IKConfig, IKTarget, make_ik
from tcot_hybrid.robot import R_DOWN, load_robot_spec
from tcot_hybrid.scene import SceneConfig
from tcot_hybrid.sim import Simulation
from tcot_hybrid.tasks import make_task
from tcot_hybrid.tasks import predicates as P
from tcot_hybrid.tasks.suites import DRAWER_OPEN_SUCCESS_M, TOOL_REACH_X


class Bench:
    """One task's scene with helpers to pose objects and the arm and let physics settle."""

    def __init__(self, task: str):
        self.spec = load_robot_spec("panda")
        self.sim = Simulation(self.spec, make_task(task), timing=TimingConfig(), scene=SceneConfig())
        self.sim.reset(np.random.default_rng(0))
        self.w = self.sim.world
        self.ik = make_ik("mink", self.spec, IKConfig(max_iters=400))
        self.q_arm = np.array(self.spec.home_q, dtype=float)

    def place(self, name, xyz, *, yaw=0.0, quat=None):
        self.w.set_pose(name, xyz, yaw)
        if quat is not None:
            j = self.w.model.joint(self.w.objects[name].joint).id
            a = self.w.model.jnt_qposadr[j]
            self.sim.data.qpos[a + 3:a + 7] = quat
        mujoco.mj_forward(self.sim.model, self.sim.data)

    def park_arm(self):
        """Arm at home, gripper open."""
        self.q_arm = np.array(self.spec.home_q, dtype=float)
        self.sim.set_gripper(False)

    def clamp_at(self, tcp_xyz):
        """TCP at ``tcp_xyz`` (fingers down, closing along y), gripper commanded closed."""
        res = self.ik.solve(IKTarget(np.asarray(tcp_xyz, dtype=float), R_DOWN), self.sim.q)
        assert res.converged, res
        self.q_arm = res.q
        self.sim.set_gripper(True)

    def run(self, seconds=1.0, *, freeze=None):
        """Physics with the arm held kinematically at ``q_arm`` (objects and fingers are simulated); an object
        named by ``freeze`` is held where it is (while the fingers close on it in mid-air)."""
        m, d = self.sim.model, self.sim.data
        if freeze is not None:
            j = m.joint(self.w.objects[freeze].joint).id
            a, v = m.jnt_qposadr[j], m.jnt_dofadr[j]
            pose = d.qpos[a:a + 7].copy()
        for _ in range(int(seconds / m.opt.timestep)):
            d.qpos[self.sim.arm_qpos] = self.q_arm
            d.qvel[self.sim.arm_dof] = 0.0
            if freeze is not None:
                d.qpos[a:a + 7] = pose
                d.qvel[v:v + 6] = 0.0
            mujoco.mj_step(m, d)
        d.qpos[self.sim.arm_qpos] = self.q_arm
        d.qvel[self.sim.arm_dof] = 0.0
        mujoco.mj_forward(m, d)

    def push(self, name, v_xyz):
        j = self.w.model.joint(self.w.objects[name].joint).id
        v = self.w.model.jnt_dofadr[j]
        self.sim.data.qvel[v:v + 3] = v_xyz
        mujoco.mj_forward(self.sim.model, self.sim.data)


def _tilt_x(angle):
    return (np.cos(angle / 2), np.sin(angle / 2), 0.0, 0.0)


# --- inside_container (bowl) ----------------------------------------------------------------------------

@pytest.fixture
def bowl():
    b = Bench("goal_cube_in_bowl")
    b.park_arm()
    b.run(0.3)  # the bowl settles onto the table
    c = b.w.pos("bowl")
    floor = c[2] + b.w.objects["bowl"].bottom
    b.floor_z, b.centre = floor, c
    return b


def test_cube_released_in_bowl_counts(bowl):
    bowl.place("cube", (*bowl.centre[:2], bowl.floor_z + 0.021))
    bowl.park_arm()
    bowl.run(1.0)
    assert P.inside_container(bowl.w, "cube", "bowl")
    assert bowl.sim.task.success(bowl.w)


def test_cube_clamped_on_bowl_floor_does_not_count(bowl):
    """The review's case: a cube still clamped in closed fingers on the container floor (it rests within 0.1 mm
    of the old 'grasped' height threshold, so the old predicate called it released)."""
    bowl.place("cube", (*bowl.centre[:2], bowl.floor_z + 0.021))
    bowl.clamp_at((*bowl.centre[:2], bowl.floor_z + 0.02))
    bowl.run(1.0)
    assert bowl.w.touching("cube", bowl.w.finger_geoms) and not bowl.w.fingers_open()
    assert bowl.w.pos("cube")[2] - bowl.floor_z == pytest.approx(0.02, abs=0.003)  # on the floor
    assert not P.released(bowl.w, "cube")
    assert not P.inside_container(bowl.w, "cube", "bowl")


def test_cube_clamped_over_bowl_does_not_count(bowl):
    bowl.place("cube", (*bowl.centre[:2], bowl.floor_z + 0.04))  # 2 cm above the floor
    bowl.clamp_at((*bowl.centre[:2], bowl.floor_z + 0.04))
    bowl.run(0.5, freeze="cube")  # the fingers close on it in mid-air
    bowl.run(0.5)
    assert bowl.w.pos("cube")[2] > bowl.floor_z + 0.03
    assert not P.inside_container(bowl.w, "cube", "bowl")


def test_cube_resting_on_bowl_rim_does_not_count(bowl):
    info = bowl.w.objects["bowl"]
    rim_r = info.inner_half + 0.004  # on the wall
    bowl.place("cube", (bowl.centre[0] + rim_r, bowl.centre[1], bowl.centre[2] + info.rim_top + 0.02))
    bowl.park_arm()
    mujoco.mj_forward(bowl.sim.model, bowl.sim.data)  # judged at once, before it slides off
    assert not P.inside_container(bowl.w, "cube", "bowl")


def test_cube_tipped_in_bowl_does_not_count(bowl):
    bowl.place("cube", (*bowl.centre[:2], bowl.floor_z + 0.0283), quat=_tilt_x(np.pi / 4))  # on an edge
    bowl.park_arm()
    assert not P.upright(bowl.w, "cube")
    assert not P.inside_container(bowl.w, "cube", "bowl")


def test_cube_moving_in_bowl_does_not_count(bowl):
    bowl.place("cube", (*bowl.centre[:2], bowl.floor_z + 0.021))
    bowl.park_arm()
    bowl.run(0.5)
    assert P.inside_container(bowl.w, "cube", "bowl")
    bowl.push("cube", (0.2, 0.0, 0.0))
    assert not P.settled(bowl.w, "cube")
    assert not P.inside_container(bowl.w, "cube", "bowl")


def test_bowl_footprint_edge(bowl):
    r = bowl.w.objects["bowl"].inner_half - P.BOWL_MARGIN_M
    for dr, expected in ((-0.003, True), (0.003, False)):
        bowl.place("cube", (bowl.centre[0] + r + dr, bowl.centre[1], bowl.floor_z + 0.02))
        bowl.park_arm()
        assert P.inside_container(bowl.w, "cube", "bowl") is expected, dr


def test_rim_is_measured_from_the_rim_top(bowl):
    """An object whose bottom is above the wall's top edge is not inside, whatever the floor thickness."""
    info = bowl.w.objects["bowl"]
    assert info.rim_top == pytest.approx(info.bottom - 0.005 + info.rim_height)  # floor 5 mm thick
    bowl.place("cube", (*bowl.centre[:2], bowl.centre[2] + info.rim_top + 0.02 + 0.002))
    bowl.park_arm()
    assert not P.inside_container(bowl.w, "cube", "bowl", tol_z=1.0)  # on-floor check off: only the rim decides


# --- inside_container (basket): a tipped cylinder ------------------------------------------------------

def test_cylinder_upright_in_basket_counts_tipped_does_not():
    b = Bench("object_green_cylinder_in_basket")
    b.park_arm()
    b.run(0.3)
    c = b.w.pos("basket")
    floor = c[2] + b.w.objects["basket"].bottom
    cyl = b.sim.task.target
    b.park_arm()
    b.place(cyl, (*c[:2], floor + b.w.objects[cyl].half_height + 0.001))
    b.run(0.8)
    assert P.inside_container(b.w, cyl, "basket")
    b.place(cyl, (*c[:2], floor + 0.021), quat=_tilt_x(np.pi / 2))  # lying on its side
    b.run(0.8)
    assert not P.upright(b.w, cyl)
    assert not P.inside_container(b.w, cyl, "basket")


# --- resting_on (plate) ---------------------------------------------------------------------------------

@pytest.fixture
def plate():
    b = Bench("goal_cube_on_plate")
    b.park_arm()
    b.run(0.3)
    q = b.w.pos("plate")
    b.top_z, b.centre = q[2] + b.w.objects["plate"].half_height, q
    return b


def test_cube_released_on_plate_counts(plate):
    plate.place("cube", (*plate.centre[:2], plate.top_z + 0.021))
    plate.park_arm()
    plate.run(1.0)
    assert P.resting_on(plate.w, "cube", "plate") and plate.sim.task.success(plate.w)


def test_cube_clamped_on_plate_does_not_count(plate):
    plate.place("cube", (*plate.centre[:2], plate.top_z + 0.021))
    plate.clamp_at((*plate.centre[:2], plate.top_z + 0.02))
    plate.run(1.0)
    assert plate.w.touching("cube", plate.w.finger_geoms)
    assert not P.resting_on(plate.w, "cube", "plate")


def test_cube_tipped_on_plate_does_not_count(plate):
    plate.place("cube", (*plate.centre[:2], plate.top_z + 0.0283), quat=_tilt_x(np.pi / 4))  # balanced on an edge
    plate.park_arm()
    assert not P.resting_on(plate.w, "cube", "plate")


def test_cube_moving_on_plate_does_not_count(plate):
    plate.place("cube", (*plate.centre[:2], plate.top_z + 0.021))
    plate.park_arm()
    plate.run(0.5)
    plate.push("cube", (0.0, 0.15, 0.0))
    assert not P.resting_on(plate.w, "cube", "plate")


def test_plate_footprint_edge(plate):
    r = plate.w.objects["plate"].inner_half - P.FOOTPRINT_MARGIN_M
    for dr, expected in ((-0.003, True), (0.003, False)):
        plate.place("cube", (plate.centre[0], plate.centre[1] + r + dr, plate.top_z + 0.02))
        plate.park_arm()
        assert P.resting_on(plate.w, "cube", "plate") is expected, dr


# --- stacked_on -----------------------------------------------------------------------------------------

@pytest.fixture
def stack():
    b = Bench("long_stack_three_blocks")
    b.park_arm()
    b.run(0.3)
    b.base = b.w.pos("red_block")
    return b


def test_block_released_on_block_counts(stack):
    stack.place("green_block", (*stack.base[:2], stack.base[2] + 0.041))
    stack.run(1.0)
    assert P.stacked_on(stack.w, "green_block", "red_block")


def test_block_clamped_on_block_does_not_count(stack):
    stack.place("green_block", (*stack.base[:2], stack.base[2] + 0.041))
    stack.clamp_at((*stack.base[:2], stack.base[2] + 0.04))
    stack.run(1.0)
    assert stack.w.touching("green_block", stack.w.finger_geoms)
    assert not P.stacked_on(stack.w, "green_block", "red_block")


def test_block_tipped_moving_or_off_centre_does_not_count(stack):
    stack.place("green_block", (*stack.base[:2], stack.base[2] + 0.0483), quat=_tilt_x(np.pi / 4))
    assert not P.stacked_on(stack.w, "green_block", "red_block")
    stack.place("green_block", (*stack.base[:2], stack.base[2] + 0.04))
    stack.push("green_block", (0.1, 0.0, 0.0))
    assert not P.stacked_on(stack.w, "green_block", "red_block")
    for dx, expected in ((0.019, True), (0.021, False)):  # centres within the smaller half-size (2 cm)
        stack.place("green_block", (stack.base[0] + dx, stack.base[1], stack.base[2] + 0.04))
        assert P.stacked_on(stack.w, "green_block", "red_block") is expected, dx


# --- drawer and tool ------------------------------------------------------------------------------------

def test_open_drawer_needs_the_handle_let_go():
    b = Bench("goal_open_drawer")
    task = b.sim.task
    slide = b.w.model.jnt_qposadr[b.w.model.joint("drawer_slide").id]
    b.sim.data.qpos[slide] = DRAWER_OPEN_SUCCESS_M + 0.02
    b.park_arm()
    b.run(0.3)
    assert task.success(b.w)
    b.sim.data.qpos[slide] = DRAWER_OPEN_SUCCESS_M - 0.005
    b.run(0.3)
    assert not task.success(b.w)  # not open far enough
    b.sim.data.qpos[slide] = DRAWER_OPEN_SUCCESS_M + 0.02
    mujoco.mj_forward(b.sim.model, b.sim.data)
    handle = b.w.data.geom_xpos[b.w.model.geom("drawer_handle").id].copy()
    b.clamp_at(handle)
    b.run(0.6)
    assert b.w.touching("drawer", b.w.finger_geoms)
    assert task.drawer_open(b.w) and not task.success(b.w)  # open, but still held


def test_tool_task_needs_the_cube_in_reach_and_still():
    b = Bench("tool_pull_cube_with_stick")
    task = b.sim.task
    b.park_arm()
    b.place("cube", (TOOL_REACH_X - 0.03, 0.0, 0.021))
    b.run(0.5)
    assert task.success(b.w)
    b.push("cube", (-0.2, 0.0, 0.0))
    assert not task.success(b.w)  # still moving
    b.place("cube", (TOOL_REACH_X + 0.005, 0.0, 0.021))
    b.run(0.5)
    assert not task.success(b.w)  # just out of reach


def test_fingers_open_follows_the_command():
    b = Bench("goal_cube_on_plate")
    b.sim.set_gripper(True)
    assert not b.w.fingers_open()
    b.sim.set_gripper(False)
    assert b.w.fingers_open()
