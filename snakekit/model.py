"""The robot description: one frozen spec, and the URDF and MJCF generated from it.

The arm is five MX-28 servos in a row with parallel vertical joint axes, so it moves in the
horizontal plane. Frames (one convention for the whole kit):

* ``world``: origin on the axis of joint 1, in the plane of motion; x points along the
  arm at home, z up. Poses are written ``T_world_<frame>``.
* ``link<i>``: rotates with joint i; its origin is on the axis of joint i, x along the link.
* ``tool``: the tool point, ``tool_offset`` beyond joint 5 along link 5's x axis.

Run ``python -m snakekit.model`` to regenerate ``snakekit/assets/snake.urdf`` and
``snake.xml`` from :data:`SPEC`, and ``python -m snakekit.model --check`` to verify the
committed files are current (the test suite does this).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ASSETS = Path(__file__).resolve().parent / "assets"
URDF_PATH = ASSETS / "snake.urdf"
MJCF_PATH = ASSETS / "snake.xml"


@dataclass(frozen=True)
class ServoSpec:
    """A Dynamixel MX-28(2.0) at 12 V, as the simulator models it.

    Attributes:
        mass: servo mass [kg].
        size: case size (length along the link, width, height) [m].
        horn_offset: distance from the case centre to the output axis, along the length [m].
        stall_torque: torque limit of the position loop [N m].
        kp: position loop stiffness [N m/rad].
        kv: position loop velocity damping [N m s/rad].
        damping: back-EMF damping with torque on [N m s/rad].
        frictionloss: dry friction [N m].
        armature: reflected rotor inertia [kg m^2].
        model_number: value of control-table address 0.
    """

    mass: float = 0.077
    size: tuple[float, float, float] = (0.0506, 0.0356, 0.0355)
    horn_offset: float = 0.0133
    stall_torque: float = 2.5
    kp: float = 15.0
    kv: float = 0.3
    damping: float = 0.43
    frictionloss: float = 0.07
    armature: float = 0.005
    model_number: int = 30


@dataclass(frozen=True)
class SnakeSpec:
    """Everything that defines the arm. SI units: m, kg, rad, s.

    Attributes:
        n_joints: number of revolute joints.
        link_length: distance between consecutive joint axes [m].
        tool_offset: tool point beyond the last joint axis [m].
        lower, upper: joint position limits [rad] (the hardware ones, +-1.57).
        velocity_limit: joint speed limit [rad/s].
        servo_ids: Dynamixel IDs from base to tip.
        link_mass: mass of one printed link bracket [kg].
        tool_mass: mass of the tool tip [kg].
        collision_margin: the least distance two links that are not neighbours in the chain
            may come to each other [m]: a goal or path that brings them closer is refused
            (:mod:`snakekit.collision`).
        servo: the servo model.
    """

    n_joints: int = 5
    link_length: float = 0.071
    tool_offset: float = 0.0475
    lower: float = -1.57
    upper: float = 1.57
    velocity_limit: float = 1.5
    servo_ids: tuple[int, ...] = (1, 2, 3, 4, 5)
    link_mass: float = 0.012
    tool_mass: float = 0.005
    collision_margin: float = 0.005
    servo: ServoSpec = ServoSpec()

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(f"joint{i + 1}" for i in range(self.n_joints))

    @property
    def lengths(self) -> np.ndarray:
        """Distance from each joint axis to the next axis (or to the tool) [m]."""
        return np.array([self.link_length] * (self.n_joints - 1) + [self.tool_offset])

    @property
    def reach(self) -> float:
        """Distance from joint 1 to the tool with the arm straight [m]."""
        return float(self.lengths.sum())

    @property
    def lower_limits(self) -> np.ndarray:
        return np.full(self.n_joints, self.lower)

    @property
    def upper_limits(self) -> np.ndarray:
        return np.full(self.n_joints, self.upper)

    @property
    def home(self) -> np.ndarray:
        return np.zeros(self.n_joints)


SPEC = SnakeSpec()


# --- mass properties -------------------------------------------------------------------


def _box_inertia(mass: float, size) -> np.ndarray:
    a, b, c = size
    return mass / 12.0 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])


def _combine(parts) -> tuple[float, np.ndarray, np.ndarray]:
    """Mass, centre of mass and inertia about it of boxes ``(mass, centre, size)``."""
    mass = sum(m for m, _, _ in parts)
    com = sum(m * np.asarray(c, float) for m, c, _ in parts) / mass
    inertia = np.zeros((3, 3))
    for m, c, size in parts:
        r = np.asarray(c, float) - com
        inertia += _box_inertia(m, size) + m * (r @ r * np.eye(3) - np.outer(r, r))
    return mass, com, inertia


@dataclass(frozen=True)
class _Box:
    name: str
    centre: tuple[float, float, float]
    size: tuple[float, float, float]
    rgba: str


BRACKET_SIZE_FRACTION = 0.62  # printed bracket length as a fraction of the link pitch
SERVO_RGBA = "0.15 0.15 0.17 1"
LINK_RGBA = "0.95 0.55 0.10 1"
TOOL_RGBA = "0.85 0.10 0.10 1"


def _link_geometry(spec: SnakeSpec, i: int) -> tuple[list[_Box], list[tuple]]:
    """Visual boxes and mass parts of link ``i`` (0-based), in the link's frame."""
    s = spec.servo
    h = s.size[2]
    last = i == spec.n_joints - 1
    length = spec.tool_offset if last else spec.link_length
    bracket = (BRACKET_SIZE_FRACTION * length, 0.8 * s.size[1], 0.004)
    boxes = [
        _Box(f"link{i + 1}_bracket_top", (bracket[0] / 2, 0, h / 2 + 0.002), bracket, LINK_RGBA),
        _Box(f"link{i + 1}_bracket_bottom", (bracket[0] / 2, 0, -h / 2 - 0.002), bracket, LINK_RGBA),
    ]
    parts = [(spec.link_mass / 2, b.centre, b.size) for b in boxes]
    if last:
        tip = (0.012, 0.012, 0.012)
        boxes.append(_Box("tool_tip", (length - tip[0] / 2, 0, 0), tip, TOOL_RGBA))
        parts.append((spec.tool_mass, boxes[-1].centre, tip))
    else:
        centre = (length - s.horn_offset, 0.0, 0.0)
        boxes.append(_Box(f"servo{i + 2}", centre, s.size, SERVO_RGBA))
        parts.append((s.mass, centre, s.size))
    return boxes, parts


def _base_geometry(spec: SnakeSpec) -> list[_Box]:
    s = spec.servo
    return [
        _Box("servo1", (-s.horn_offset, 0, 0), s.size, SERVO_RGBA),
        _Box("base_plate", (-0.02, 0, -s.size[2] / 2 - 0.004), (0.09, 0.07, 0.008), "0.6 0.6 0.65 1"),
    ]


def base_plate(spec: SnakeSpec = SPEC) -> tuple[np.ndarray, np.ndarray]:
    """The base plate under joint 1: its centre and its size (x, y, z) [m], in the world frame
    (what a drawing of the arm seen from above puts under it)."""
    plate = next(b for b in _base_geometry(spec) if b.name == "base_plate")
    return np.array(plate.centre, dtype=float), np.array(plate.size, dtype=float)


def body_names(spec: SnakeSpec = SPEC) -> tuple[str, ...]:
    """The arm's rigid bodies from base to tip, as the URDF and MJCF name them."""
    return ("base_link", *(f"link{i + 1}" for i in range(spec.n_joints)))


def collision_points(spec: SnakeSpec = SPEC) -> list[np.ndarray]:
    """The corners (N, 3) [m] of each body's parts, in the body's frame, base to tip.

    A body's collision shape is the convex hull of these points: the servo it carries, its
    printed bracket plates and the space between them (where the servo it is driven by sits),
    so it holds every part of the body and is at most a few millimetres larger. The URDF's
    visual boxes, the MJCF's collision meshes and the collision check
    (:mod:`snakekit.collision`) all come from the same parts.
    """
    signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float)
    bodies = [_base_geometry(spec)] + [_link_geometry(spec, i)[0] for i in range(spec.n_joints)]
    return [np.vstack([np.array(b.centre) + signs * np.array(b.size) / 2 for b in boxes]) for boxes in bodies]


def link_mass_properties(spec: SnakeSpec = SPEC) -> list[tuple[float, np.ndarray, np.ndarray]]:
    """``(mass [kg], centre of mass [m], inertia about the CoM [kg m^2])`` of each link."""
    return [_combine(_link_geometry(spec, i)[1]) for i in range(spec.n_joints)]


# --- generators ------------------------------------------------------------------------


def _f(x: float) -> str:
    return f"{x:.6g}"


def _v(xs) -> str:
    return " ".join(_f(float(x)) for x in xs)


HEADER = "Generated by `python -m snakekit.model` from snakekit.model.SPEC. Do not edit."


def urdf(spec: SnakeSpec = SPEC) -> str:
    """The arm as URDF (for Pinocchio and the viewer)."""
    out = ['<?xml version="1.0"?>', f"<!-- {HEADER} -->", '<robot name="snake">']
    out += ['  <material name="servo"><color rgba="%s"/></material>' % SERVO_RGBA]
    out += ['  <material name="link"><color rgba="%s"/></material>' % LINK_RGBA]
    out += ['  <material name="tool"><color rgba="%s"/></material>' % TOOL_RGBA]
    out += ['  <material name="base"><color rgba="0.6 0.6 0.65 1"/></material>']

    def visuals(boxes):
        for b in boxes:
            mat = "servo" if b.name.startswith("servo") else "tool" if b.name == "tool_tip" else (
                "base" if b.name == "base_plate" else "link")
            out.extend([
                f'    <visual name="{b.name}">',
                f'      <origin xyz="{_v(b.centre)}" rpy="0 0 0"/>',
                f'      <geometry><box size="{_v(b.size)}"/></geometry>',
                f'      <material name="{mat}"/>',
                "    </visual>",
            ])

    out.append('  <link name="base_link">')
    visuals(_base_geometry(spec))
    out.append("  </link>")
    parent = "base_link"
    for i in range(spec.n_joints):
        boxes, parts = _link_geometry(spec, i)
        mass, com, inertia = _combine(parts)
        origin = 0.0 if i == 0 else spec.link_length
        out += [
            f'  <joint name="joint{i + 1}" type="revolute">',
            f'    <parent link="{parent}"/>',
            f'    <child link="link{i + 1}"/>',
            f'    <origin xyz="{_f(origin)} 0 0" rpy="0 0 0"/>',
            '    <axis xyz="0 0 1"/>',
            f'    <limit lower="{_f(spec.lower)}" upper="{_f(spec.upper)}" '
            f'effort="{_f(spec.servo.stall_torque)}" velocity="{_f(spec.velocity_limit)}"/>',
            f'    <dynamics damping="{_f(spec.servo.damping)}" friction="{_f(spec.servo.frictionloss)}"/>',
            "  </joint>",
            f'  <link name="link{i + 1}">',
            "    <inertial>",
            f'      <origin xyz="{_v(com)}" rpy="0 0 0"/>',
            f'      <mass value="{_f(mass)}"/>',
            '      <inertia ixx="{}" ixy="{}" ixz="{}" iyy="{}" iyz="{}" izz="{}"/>'.format(
                *(_f(inertia[a, b]) for a, b in ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)))),
            "    </inertial>",
        ]
        visuals(boxes)
        out.append("  </link>")
        parent = f"link{i + 1}"
    out += [
        '  <joint name="tool_joint" type="fixed">',
        f'    <parent link="{parent}"/>',
        '    <child link="tool"/>',
        f'    <origin xyz="{_f(spec.tool_offset)} 0 0" rpy="0 0 0"/>',
        "  </joint>",
        '  <link name="tool"/>',
        "</robot>",
    ]
    return "\n".join(out) + "\n"


def mjcf(spec: SnakeSpec = SPEC) -> str:
    """The arm as MJCF (for MuJoCo): 1 kHz physics, one MX-28 position servo per joint.

    Each actuator integrates its control (the reference velocity [rad/s]) into its state
    (the reference position [rad]); the simulator sets both from the servo profile.
    """
    s = spec.servo
    floor_z = -s.size[2] / 2 - 0.008
    out = [
        f"<!-- {HEADER} -->",
        '<mujoco model="snake">',
        '  <compiler angle="radian" autolimits="true"/>',
        # Joint axes are vertical: the links touch only each other, when the arm folds onto
        # itself. Contacts are computed between each body's collision hull (group 3, unseen)
        # and those of the bodies that are not its neighbours (<contact> below). The other constraints are the
        # joints' dry friction; PGS solves them fastest here (Task 2 differs from the Newton
        # solver's by < 1e-7 rad).
        '  <option timestep="0.001" integrator="implicitfast" solver="PGS"/>',
        "  <visual>",
        '    <global offwidth="1280" offheight="960"/>',
        '    <headlight ambient="0.35 0.35 0.35" diffuse="0.35 0.35 0.35" specular="0.1 0.1 0.1"/>',
        "  </visual>",
        "  <asset>",
        '    <texture name="grid" type="2d" builtin="checker" width="256" height="256" '
        'rgb1="0.82 0.84 0.86" rgb2="0.74 0.76 0.78"/>',
        '    <material name="grid" texture="grid" texrepeat="8 8"/>',
        *(f'    <mesh name="{name}_hull" vertex="{_v(pts.ravel())}"/>'
          for name, pts in zip(body_names(spec), collision_points(spec))),
        "  </asset>",
        "  <default>",
        '    <geom type="box" contype="0" conaffinity="0"/>',
        f'    <joint type="hinge" axis="0 0 1" range="{_f(spec.lower)} {_f(spec.upper)}" '
        f'damping="{_f(s.damping)}" frictionloss="{_f(s.frictionloss)}" armature="{_f(s.armature)}"/>',
        # The servo: the actuator state (act) is the firmware's reference position, its
        # control is the reference velocity, and the force is a PD loop clamped at stall torque.
        f'    <general dyntype="integrator" gaintype="fixed" gainprm="{_f(s.kp)}" biastype="affine" '
        f'biasprm="0 {_f(-s.kp)} {_f(-s.kv)}" actrange="{_f(spec.lower)} {_f(spec.upper)}" '
        f'forcerange="{_f(-s.stall_torque)} {_f(s.stall_torque)}"/>',
        "  </default>",
        "  <worldbody>",
        f'    <geom name="floor" type="plane" size="0.6 0.6 0.01" pos="0.12 0 {_f(floor_z)}" material="grid"/>',
        '    <light name="top" pos="0.15 -0.3 1.0" dir="0 0.3 -1" diffuse="0.45 0.45 0.45" specular="0.1 0.1 0.1"/>',
        '    <camera name="top" pos="0.12 0 0.8" xyaxes="1 0 0 0 1 0"/>',
        '    <camera name="perspective" pos="0.14 -0.36 0.3" xyaxes="1 0 0 0 0.64 0.77"/>',
    ]
    hull = '<geom name="{0}_collision" type="mesh" mesh="{0}_hull" group="3" rgba="1 0 0 0.3" mass="0"/>'
    for b in _base_geometry(spec):
        out.append(f'    <geom name="{b.name}" pos="{_v(b.centre)}" size="{_v(np.array(b.size) / 2)}" rgba="{b.rgba}"/>')
    out.append("    " + hull.format("base_link"))
    indent = "    "
    for i in range(spec.n_joints):
        boxes, parts = _link_geometry(spec, i)
        mass, com, inertia = _combine(parts)
        pos = 0.0 if i == 0 else spec.link_length
        out.append(f'{indent}<body name="link{i + 1}" pos="{_f(pos)} 0 0">')
        indent += "  "
        full = f"{_f(inertia[0, 0])} {_f(inertia[1, 1])} {_f(inertia[2, 2])} " \
               f"{_f(inertia[0, 1])} {_f(inertia[0, 2])} {_f(inertia[1, 2])}"
        out.append(f'{indent}<inertial pos="{_v(com)}" mass="{_f(mass)}" fullinertia="{full}"/>')
        out.append(f'{indent}<joint name="joint{i + 1}"/>')
        for b in boxes:
            out.append(f'{indent}<geom name="{b.name}" pos="{_v(b.centre)}" '
                       f'size="{_v(np.array(b.size) / 2)}" rgba="{b.rgba}" mass="0"/>')
        out.append(indent + hull.format(f"link{i + 1}"))
    out.append(f'{indent}<site name="tool" pos="{_f(spec.tool_offset)} 0 0" size="0.004" rgba="1 0 0 1"/>')
    for _ in range(spec.n_joints):
        indent = indent[:-2]
        out.append(f"{indent}</body>")
    out.append("  </worldbody>")
    # The pairs that may touch, listed: cheaper per step than MuJoCo's broad phase. Neighbours
    # overlap where a bracket holds a servo, so they never count as a contact.
    out.append("  <contact>")
    names = body_names(spec)
    for a in range(len(names)):
        for b in range(a + 2, len(names)):
            out.append(f'    <pair geom1="{names[a]}_collision" geom2="{names[b]}_collision"/>')
    out.append("  </contact>")
    out.append("  <actuator>")
    for name in spec.joint_names:
        out.append(f'    <general name="{name}" joint="{name}"/>')
    out.append("  </actuator>")
    out.append("  <sensor>")
    for name in spec.joint_names:
        out.append(f'    <actuatorfrc name="{name}_torque" actuator="{name}"/>')
    out.append("  </sensor>")
    out.append("</mujoco>")
    return "\n".join(out) + "\n"


GENERATED = {URDF_PATH: urdf, MJCF_PATH: mjcf}


def stale_files(spec: SnakeSpec = SPEC) -> list[Path]:
    """The generated files that differ from what ``spec`` generates now."""
    return [p for p, gen in GENERATED.items() if not p.exists() or p.read_text() != gen(spec)]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m snakekit.model", description=__doc__.split("\n")[0])
    parser.add_argument("--check", action="store_true", help="only check that the committed files are current")
    args = parser.parse_args(argv)
    stale = stale_files()
    if args.check:
        for p in stale:
            print(f"{p.name} is stale: run `python -m snakekit.model` and commit it", file=sys.stderr)
        return 1 if stale else 0
    ASSETS.mkdir(exist_ok=True)
    for p, gen in GENERATED.items():
        p.write_text(gen(SPEC))
        print(f"wrote {p.name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
