"""The task suites. They mirror LIBERO's four (spatial, object, goal, long) plus a tool-use task.

spatial: identical objects; which one to pick depends on the layout.
object:  pick the named object among distractors and put it in the basket.
goal:    one layout (cube, plate, bowl, drawer), different goals.
long:    two or more steps.
tool:    use a hooked stick to pull an out-of-reach cube closer.
"""
from __future__ import annotations

import numpy as np

from tcot_hybrid.tasks import objects as ob
from tcot_hybrid.tasks.base import (
    HookPull,
    PickPlace,
    PullDrawer,
    Task,
    World,
    sample_apart,
)
from tcot_hybrid.tasks.predicates import inside_container, released, resting_on, settled, stacked_on
from tcot_hybrid.tasks.registry import register_task

# Clearance radii [m] for layout sampling: an object's footprint plus, for graspable ones, the open
# fingers (they reach ~5.5 cm from the object's centre along y), so a grasp never hits a neighbour.
RADIUS = {"cube": 0.045, "cylinder": 0.045, "plate": 0.085, "bowl": 0.09, "basket": 0.1}
DRAWER_OPEN_SUCCESS_M = 0.12  # [m] slide travel that counts as "open"
DRAWER_PULL_M = 0.17  # [m] how far the oracle pulls (leaves the interior exposed for a cube)


def _yaw(rng, spread=0.3):
    return float(rng.uniform(-spread, spread))


def _place(world: World, rng, regions, kinds: dict[str, str], *, yaw_spread: float = 0.3):
    """Sample non-overlapping xy in each object's region; receptacles keep yaw 0, others get a random yaw."""
    xy = sample_apart(rng, regions, {n: RADIUS[k] for n, k in kinds.items()})
    for name, p in xy.items():
        o = world.objects[name]
        yaw = 0.0 if kinds[name] in ("basket", "bowl", "plate") else _yaw(rng, yaw_spread)
        world.set_pose(name, (p[0], p[1], o.rest_z + 0.001), yaw)


def _on_surface_point(surface: str, obj: str):
    """Release point: centre of a plate-like surface at the object's resting centre height."""
    def f(world: World):
        q = world.pos(surface)
        s, o = world.objects[surface], world.objects[obj]
        return np.array([q[0], q[1], q[2] + s.half_height + o.half_height])
    f.target = surface
    return f


def _in_container_point(container: str, obj: str, offset=(0.0, 0.0)):
    def f(world: World):
        c, o = world.objects[container], world.objects[obj]
        base = world.pos(container) + world.rot(container) @ np.array([offset[0], offset[1], c.bottom])
        return base + np.array([0, 0, o.half_height])
    f.target = container
    return f


def _in_open_drawer_point(drawer: str, obj: str):
    """Centre of the drawer's interior once it has been pulled open by DRAWER_PULL_M (global plans are
    made while it is still closed)."""
    inner = _in_container_point(drawer, obj, (0.01 + ob.DRAWER_INNER[0], 0.0))

    def f(world: World):
        still_to_open = max(DRAWER_PULL_M - world.joint_q(f"{drawer}_slide"), 0.0)
        return inner(world) - np.array([still_to_open, 0.0, 0.0])
    f.target = drawer
    return f


def _on_top_of(*column: str):
    """Release point for column[-1] on top of column[0], with column[1:-1] stacked in between.

    A global plan is made before the lower blocks move, so the point is computed from the bottom
    block, which stays put, and the heights of everything that will be stacked on it.
    """
    def f(world: World):
        b = world.pos(column[0])
        h = [world.objects[n].half_height for n in column]
        return b + np.array([0, 0, h[0] + 2 * sum(h[1:-1]) + h[-1]])
    f.target = column[0]
    return f


# --- spatial ------------------------------------------------------------------------------------------

@register_task
class SpatialLeftCubeOnPlate(Task):
    name = "spatial_left_cube_on_plate"
    suite = "spatial"
    instruction = "put the cube on the left on the plate"
    time_limit_s = 25.0

    def add_objects(self, spec):
        return {o.name: o for o in (ob.cube(spec, "cube_a", ob.RED), ob.cube(spec, "cube_b", ob.RED),
                                    ob.plate(spec))}

    def reset(self, world, rng):
        # Cubes in a front row, clearly apart in y; the plate behind them.
        ya = rng.uniform(0.06, 0.24) * rng.choice([-1, 1])
        yb = -np.sign(ya) * rng.uniform(0.06, 0.24)
        xa, xb = rng.uniform(0.36, 0.46, size=2)
        world.set_pose("cube_a", (xa, ya, 0.021), _yaw(rng))
        world.set_pose("cube_b", (xb, yb, 0.021), _yaw(rng))
        world.set_pose("plate", (rng.uniform(0.56, 0.62), rng.uniform(-0.12, 0.12), 0.007), 0.0)
        self.target = "cube_a" if ya > yb else "cube_b"  # left = +y in the robot's frame

    def success(self, world):
        return resting_on(world, self.target, "plate")

    def skills(self):
        return [PickPlace(self.target, _on_surface_point("plate", self.target), self.success)]


@register_task
class SpatialNearCubeInBowl(Task):
    name = "spatial_near_cube_in_bowl"
    suite = "spatial"
    instruction = "put the cube closest to the robot in the bowl"
    time_limit_s = 25.0

    def add_objects(self, spec):
        return {o.name: o for o in (ob.cube(spec, "cube_a", ob.GREEN), ob.cube(spec, "cube_b", ob.GREEN),
                                    ob.bowl(spec))}

    def reset(self, world, rng):
        side = rng.choice([-1, 1])
        xa = rng.uniform(0.34, 0.42)
        xb = rng.uniform(0.52, 0.60)
        ya, yb = side * rng.uniform(0.08, 0.22, size=2)
        order = rng.permutation(["cube_a", "cube_b"])
        world.set_pose(order[0], (xa, ya, 0.021), _yaw(rng))
        world.set_pose(order[1], (xb, yb, 0.021), _yaw(rng))
        world.set_pose("bowl", (rng.uniform(0.42, 0.55), -side * rng.uniform(0.13, 0.22), 0.03), 0.0)
        self.target = str(order[0])

    def success(self, world):
        return inside_container(world, self.target, "bowl")

    def skills(self):
        return [PickPlace(self.target, _in_container_point("bowl", self.target), self.success)]


# --- object -------------------------------------------------------------------------------------------

class _ObjectSuite(Task):
    suite = "object"
    time_limit_s = 25.0
    target = ""
    KINDS = {"red_cube": "cube", "blue_cube": "cube", "green_cylinder": "cylinder",
             "yellow_cylinder": "cylinder", "basket": "basket"}

    def add_objects(self, spec):
        objs = (ob.cube(spec, "red_cube", ob.RED), ob.cube(spec, "blue_cube", ob.BLUE),
                ob.cylinder(spec, "green_cylinder", ob.GREEN), ob.cylinder(spec, "yellow_cylinder", ob.YELLOW),
                ob.basket(spec))
        return {o.name: o for o in objs}

    def reset(self, world, rng):
        side = rng.choice([-1, 1])  # basket on one side, the four objects on the other half of the table
        lo, hi = sorted((-side * 0.25, side * 0.04))
        regions = {name: (0.33, 0.62, lo, hi) for name in ("red_cube", "blue_cube", "green_cylinder", "yellow_cylinder")}
        regions["basket"] = (0.45, 0.58, *sorted((side * 0.17, side * 0.24)))
        _place(world, rng, regions, self.KINDS, yaw_spread=0.3)

    def success(self, world):
        return inside_container(world, self.target, "basket")

    def skills(self):
        return [PickPlace(self.target, _in_container_point("basket", self.target), self.success)]


@register_task
class ObjectRedCubeInBasket(_ObjectSuite):
    name = "object_red_cube_in_basket"
    instruction = "put the red cube in the basket"
    target = "red_cube"


@register_task
class ObjectGreenCylinderInBasket(_ObjectSuite):
    name = "object_green_cylinder_in_basket"
    instruction = "put the green cylinder in the basket"
    target = "green_cylinder"


@register_task
class ObjectBlueCubeInBasket(_ObjectSuite):
    name = "object_blue_cube_in_basket"
    instruction = "put the blue cube in the basket"
    target = "blue_cube"


# --- goal: one layout, different goals ---------------------------------------------------------------

class _GoalLayout(Task):
    suite = "goal"
    time_limit_s = 25.0

    def add_objects(self, spec):
        objs = (ob.cube(spec, "cube", ob.RED), ob.plate(spec), ob.bowl(spec), ob.drawer(spec))
        return {o.name: o for o in objs}

    def reset(self, world, rng):
        cab = world.model.body("drawer_cabinet").id
        world.model.body_pos[cab] = (0.68, rng.uniform(-0.02, 0.02), 0.0)
        world.set_pose("cube", (rng.uniform(0.34, 0.42), rng.uniform(-0.07, 0.07), 0.021), _yaw(rng))
        world.set_pose("plate", (rng.uniform(0.40, 0.52), rng.uniform(0.21, 0.26), 0.007), 0.0)
        world.set_pose("bowl", (rng.uniform(0.40, 0.52), rng.uniform(-0.27, -0.23), 0.03), 0.0)

    def drawer_open(self, world):
        return world.joint_q("drawer_slide") >= DRAWER_OPEN_SUCCESS_M


@register_task
class GoalCubeOnPlate(_GoalLayout):
    name = "goal_cube_on_plate"
    instruction = "put the cube on the plate"

    def success(self, world):
        return resting_on(world, "cube", "plate")

    def skills(self):
        return [PickPlace("cube", _on_surface_point("plate", "cube"), self.success)]


@register_task
class GoalCubeInBowl(_GoalLayout):
    name = "goal_cube_in_bowl"
    instruction = "put the cube in the bowl"

    def success(self, world):
        return inside_container(world, "cube", "bowl")

    def skills(self):
        return [PickPlace("cube", _in_container_point("bowl", "cube"), self.success)]


@register_task
class GoalOpenDrawer(_GoalLayout):
    name = "goal_open_drawer"
    instruction = "open the drawer"

    def success(self, world):
        """Open (slide travel >= DRAWER_OPEN_SUCCESS_M), the handle let go (released) and the drawer still."""
        return bool(self.drawer_open(world) and released(world, "drawer") and settled(world, "drawer"))

    def skills(self):
        return [PullDrawer("drawer", distance=DRAWER_PULL_M, achieved=self.success)]


# --- long ---------------------------------------------------------------------------------------------

@register_task
class LongBothCubesInBowl(Task):
    name = "long_both_cubes_in_bowl"
    suite = "long"
    instruction = "put both cubes in the bowl"
    time_limit_s = 40.0

    def add_objects(self, spec):
        return {o.name: o for o in (ob.cube(spec, "red_cube", ob.RED), ob.cube(spec, "blue_cube", ob.BLUE),
                                    ob.bowl(spec, inner_radius=0.08))}

    def reset(self, world, rng):
        side = rng.choice([-1, 1])
        lo, hi = sorted((side * 0.02, side * 0.25))
        _place(world, rng, {"red_cube": (0.34, 0.6, lo, hi), "blue_cube": (0.34, 0.6, lo, hi),
                            "bowl": (0.42, 0.55, *sorted((-side * 0.12, -side * 0.2)))},
               {"red_cube": "cube", "blue_cube": "cube", "bowl": "bowl"})

    def _in(self, name):
        return lambda world: inside_container(world, name, "bowl")

    def success(self, world):
        return self._in("red_cube")(world) and self._in("blue_cube")(world)

    def skills(self):
        return [PickPlace("red_cube", _in_container_point("bowl", "red_cube", (0.0, 0.032)), self._in("red_cube")),
                PickPlace("blue_cube", _in_container_point("bowl", "blue_cube", (0.0, -0.032)),
                          self._in("blue_cube"))]


@register_task
class LongStackThreeBlocks(Task):
    name = "long_stack_three_blocks"
    suite = "long"
    instruction = "stack the green block on the red block and the blue block on the green block"
    time_limit_s = 40.0

    def add_objects(self, spec):
        return {o.name: o for o in (ob.cube(spec, "red_block", ob.RED), ob.cube(spec, "green_block", ob.GREEN),
                                    ob.cube(spec, "blue_block", ob.BLUE))}

    def reset(self, world, rng):
        region = (0.36, 0.6, -0.22, 0.22)
        _place(world, rng, {n: region for n in ("red_block", "green_block", "blue_block")},
               {n: "cube" for n in ("red_block", "green_block", "blue_block")})

    def success(self, world):
        return stacked_on(world, "green_block", "red_block") and stacked_on(world, "blue_block", "green_block")

    def skills(self):
        return [PickPlace("green_block", _on_top_of("red_block", "green_block"),
                          lambda w: stacked_on(w, "green_block", "red_block")),
                PickPlace("blue_block", _on_top_of("red_block", "green_block", "blue_block"), self.success)]


@register_task
class LongOpenDrawerPutCube(_GoalLayout):
    name = "long_open_drawer_put_cube"
    suite = "long"
    instruction = "open the drawer and put the cube in it"
    time_limit_s = 40.0

    def success(self, world):
        return self.drawer_open(world) and inside_container(world, "cube", "drawer")

    def skills(self):
        return [PullDrawer("drawer", distance=DRAWER_PULL_M, achieved=self.drawer_open),
                PickPlace("cube", _in_open_drawer_point("drawer", "cube"), self.success)]


# --- tool use -----------------------------------------------------------------------------------------

TOOL_REACH_X = 0.68  # [m] the cube counts as "within reach" once its centre is nearer than this


@register_task
class ToolPullCubeWithStick(Task):
    name = "tool_pull_cube_with_stick"
    suite = "tool"
    instruction = "use the stick to pull the cube into reach"
    time_limit_s = 35.0

    def add_objects(self, spec):
        return {o.name: o for o in (ob.cube(spec, "cube", ob.RED), ob.stick(spec))}

    def reset(self, world, rng):
        cy = rng.uniform(-0.1, 0.1)
        world.set_pose("cube", (rng.uniform(0.78, 0.83), cy, 0.021), _yaw(rng, 0.2))
        sy = cy + rng.choice([-1, 1]) * rng.uniform(0.16, 0.2)
        world.set_pose("stick", (rng.uniform(0.3, 0.34), sy, 0.0105), _yaw(rng, 0.1))

    def success(self, world):
        """The cube's centre nearer than TOOL_REACH_X, no finger on it, and at rest (the stick may still be held:
        the cube, not the tool, is what is delivered)."""
        return bool(world.pos("cube")[0] < TOOL_REACH_X and not world.touching("cube", world.finger_geoms)
                    and settled(world, "cube"))

    def skills(self):
        return [HookPull("stick", "cube", pull_to_x=0.33, achieved=self.success)]
