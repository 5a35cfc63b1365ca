"""Write config/robots/robosimian.urdf and config/robots/biped.urdf (run from the repository root).

robosimian
    JPL's RoboSimian with the kinematics and inertias published in Project Chrono's model (the
    figures and their source are below): a 46.66 kg chassis and four identical 7-DOF limbs of
    18.65 kg (121.25 kg in all, the limbs 61.5 % of it; the thesis 000, II.C: "approximately 60
    percent"). Chrono's frames are kept link by link, so each link's COM and inertia are the
    published numbers; only base_link is Chrono's chassis frame turned over to REP-103 axes. The
    limbs are identical, mounted at four rotations: the left-front and right-rear limbs are the
    front-right one mirrored at negated joint angles, the left-rear one is it turned by pi.
biped
    A small humanoid made for gait_nodes: 31 kg, pelvis and torso, two 6-DOF legs (hip yaw,
    roll, pitch, knee, ankle pitch, roll) with 0.3 m thigh and shin, flat feet with the sole
    frame 0.05 m below the ankle. Every link frame is parallel to the base at the zero
    configuration, so that a reflection only changes signs of positions and axes.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

TWO_PI = 2.0 * math.pi


def _fmt(values, digits: int = 6) -> str:
    return ' '.join(f'{v:.{digits}g}' for v in values)


def box_inertia(mass, size):
    """Principal inertias [kg m^2] of a solid box of ``size`` (x, y, z) [m]."""
    x, y, z = size
    return np.array([y * y + z * z, x * x + z * z, x * x + y * y]) * mass / 12.0


def rod_inertia(mass, length, radius):
    """Cylinder along z."""
    side = mass * (3 * radius ** 2 + length ** 2) / 12.0
    return np.array([side, side, 0.5 * mass * radius ** 2])


class Urdf:
    """URDF text, link by link; numbers written to ``digits`` significant digits."""

    def __init__(self, name, digits: int = 6):
        self.digits = digits
        self.lines = ['<?xml version="1.0"?>', f'<robot name="{name}">']

    def _n(self, value) -> str:
        return f'{value:.{self.digits}g}'

    def _v(self, values) -> str:
        return _fmt(values, self.digits)

    def link(self, name, mass=None, com=(0, 0, 0), inertia=(0, 0, 0), visual=None,
             inertia_xy=(0, 0, 0), inertia_rpy=(0, 0, 0)):
        """A link; ``inertia`` (xx, yy, zz) and ``inertia_xy`` (xy, xz, yz) about the COM."""
        self.lines.append(f'  <link name="{name}">')
        if mass is not None:
            n = self._n
            (ixx, iyy, izz), (ixy, ixz, iyz) = inertia, inertia_xy
            self.lines += [
                '    <inertial>',
                f'      <origin xyz="{self._v(com)}" rpy="{self._v(inertia_rpy)}"/>',
                f'      <mass value="{n(mass)}"/>',
                f'      <inertia ixx="{n(ixx)}" ixy="{n(ixy)}" ixz="{n(ixz)}" iyy="{n(iyy)}" '
                f'iyz="{n(iyz)}" izz="{n(izz)}"/>',
                '    </inertial>']
        if visual is not None:
            origin, geometry = visual
            self.lines += [
                '    <visual>',
                f'      <origin xyz="{self._v(origin)}" rpy="0 0 0"/>',
                f'      <geometry>{geometry}</geometry>',
                '    </visual>']
        self.lines.append('  </link>')

    def joint(self, name, parent, child, xyz, axis=None, limits=None, velocity=None,
              rpy=(0, 0, 0)):
        """A revolute joint about ``axis``, or a fixed one without; origin ``xyz``, ``rpy``."""
        kind = 'fixed' if axis is None else 'revolute'
        self.lines += [
            f'  <joint name="{name}" type="{kind}">',
            f'    <parent link="{parent}"/>',
            f'    <child link="{child}"/>',
            f'    <origin xyz="{self._v(xyz)}" rpy="{self._v(rpy)}"/>']
        if axis is not None:
            lower, upper = limits
            self.lines += [
                f'    <axis xyz="{self._v(axis)}"/>',
                f'    <limit lower="{self._n(lower)}" upper="{self._n(upper)}" effort="500" '
                f'velocity="{self._n(velocity)}"/>']
        self.lines.append('  </joint>')

    def text(self):
        """The whole URDF."""
        return '\n'.join(self.lines + ['</robot>', ''])


def cylinder(length, radius):
    """URDF cylinder geometry."""
    return f'<cylinder length="{length:.6g}" radius="{radius:.6g}"/>'


def box(size):
    """URDF box geometry."""
    return f'<box size="{_fmt(size)}"/>'


def sphere(radius):
    """URDF sphere geometry."""
    return f'<sphere radius="{radius:.6g}"/>'


# -- robosimian --------------------------------------------------------------------------------

# Figures of JPL's RoboSimian as published in Project Chrono's model
# (projectchrono/chrono, src/chrono_models/robot/robosimian/RoboSimian.cpp, BSD-3-Clause, read at
# commit 0495c2ec): the numbers only. Lengths [m], masses [kg], inertias [kg m^2] about the link's
# COM in the link frame, as (xx, yy, zz) and products (xy, xz, yz).
#
# Chrono's chassis frame is ours turned over: the demos place the robot rotated by pi about x,
# so Chrono's z points down and its y to the right. CHRONO_TO_BASE maps Chrono's chassis frame
# into base_link (REP-103: x forward, y left, z up).
#
# Chrono prints angles to 5 decimals: 3.14159, 1.57080, 0.26180, 2.87979, 3.40339 are pi, pi/2,
# pi/12, 11 pi/12 and 13 pi/12 (within 3e-6 rad); they are written here exactly, so that the four
# limbs are exact mirror images of each other. The wheel joint's -1.57000 is kept as published.
CHRONO_TO_BASE_RPY = (math.pi, 0.0, 0.0)
RS_CHASSIS = {
    'mass_kg': 46.658335,
    'com_m': (0.040288, -0.001937, -0.073574),   # in Chrono's chassis frame
    'inertia_xx': (1.272134, 2.568776, 3.086984),
    'inertia_xy': (0.008890, -0.13942, 0.000325),
    'box_m': (0.93, 0.50, 0.238),                 # visual only: the body's outer box
}
# Limb mounts on the chassis (Chrono frame): position and roll-pitch-yaw of the limb's link 0.
RS_MOUNTS = {
    'fr': ((+0.29326, +0.20940, 0.03650), (0.0, -math.pi / 2, -math.pi / 12)),
    'rr': ((-0.29326, +0.20940, 0.03650), (0.0, -math.pi / 2, +math.pi / 12)),
    'rl': ((-0.29326, -0.20940, 0.03650), (0.0, -math.pi / 2, 11 * math.pi / 12)),
    'fl': ((+0.29326, -0.20940, 0.03650), (0.0, -math.pi / 2, 13 * math.pi / 12)),
}
# Links: name -> (mass, com, inertia_xx, inertia_xy).
RS_LINKS = {
    'pitch': (0.428770, (-0.050402, 0.012816, 0.0), (0.000670, 0.000955, 0.000726),
              (0.000062, 0.0, 0.0)),
    'roll': (4.078540, (0.066970, -0.090099, -0.000084), (0.010580, 0.025014, 0.031182),
             (-0.008765, -0.000002, 0.000007)),
    'ft_adapter': (0.253735, (-0.00531, -0.00060, -0.001873), (0.00042, 0.00024, 0.00023),
                   (0.0, 0.0, 0.0)),
    'ft_sensor': (0.195418, (-0.000135, 0.000118, 0.000084), (0.000086, 0.000056, 0.000057),
                  (0.0, 0.0, 0.0)),
    'wheel_mount': (3.1775, (-0.005260, 0.042308, 0.000088), (0.010977, 0.005330, 0.011405),
                    (0.000702, 0.000026, -0.000028)),
    'wheel': (1.499326, (0.0, 0.0, -0.000229), (0.006378, 0.006377, 0.009155), (0.0, 0.0, 0.0)),
}
# The limb chain, base to tip: (joint k, parent link, link, origin xyz, origin rpy, axis, link
# figures). Seven revolute joints alternate about the link's long axis (x) and a bending axis
# (-y); each bending joint's link reaches 0.28650 m along and 0.117 m across to the next pair.
RS_CHAIN = (
    (1, 0, (0.17203, 0.0, 0.0), (math.pi, 0.0, 0.0), (1, 0, 0), 'pitch'),
    (2, 1, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0, -1, 0), 'roll'),
    (3, 2, (0.28650, -0.11700, 0.0), (0.0, 0.0, 0.0), (1, 0, 0), 'pitch'),
    (4, 3, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0, -1, 0), 'roll'),
    (5, 4, (0.28650, -0.11700, 0.0), (0.0, 0.0, 0.0), (1, 0, 0), 'pitch'),
    (6, 5, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0, -1, 0), 'roll'),
    (7, 6, (0.19250, -0.11700, 0.0), (0.0, 0.0, 0.0), (1, 0, 0), 'wheel_mount'),
)
# Rigid parts after a joint: (name, parent link k, origin xyz, origin rpy, link figures).
RS_FIXED = (
    ('ft_adapter', 6, (0.20739, -0.12100, 0.0), (0.0, 0.0, 0.0), 'ft_adapter'),
    ('ft_sensor', 'ft_adapter', (0.0263755, 0.0, 0.0), (0.0, 0.0, 0.0), 'ft_sensor'),
    # The wheel's axle joint is of no use for walking; the wheel rides along as a rigid part.
    ('wheel', 7, (0.12024, 0.17200, 0.0), (-1.57000, 0.0, 0.0), 'wheel'),
)
# The foot (not in Chrono's model, whose limbs end in a wheel mount): the thesis' end effector,
# a 0.055 m radius foot (thesis 000, IV.A). Its centre is on joint 7's axis where the wheel mount
# (a 0.0545 m radius body, link 7) is centred, 0.12024 m beyond joint 7; the sole, the contact
# point and the foot frame, is a radius further. The foot frame is parallel to base_link at zero
# joint angles (every limb then hangs straight down), so a level foot has roll = pitch = 0.
RS_FOOT_CENTRE_BEYOND_JOINT_7_M = 0.12024
RS_FOOT_RADIUS_M = 0.055
# Joint limits [rad]: Chrono's model has none; the real limb turns far each way, so the limits
# leave room for every IK family. Velocity limit: thesis II.D.
RS_LIMIT_RAD = TWO_PI
RS_VELOCITY_LIMIT_RAD_S = 1.0


def rpy_matrix(rpy) -> np.ndarray:
    """Rotation of a URDF (and Chrono) roll-pitch-yaw: Rz(yaw) Ry(pitch) Rx(roll)."""
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = (math.cos(r), math.sin(r), math.cos(p), math.sin(p),
                              math.cos(y), math.sin(y))
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return rz @ ry @ rx


def matrix_rpy(rotation) -> tuple[float, float, float]:
    """Roll-pitch-yaw of a rotation (the inverse of :func:`rpy_matrix` away from pitch +-pi/2)."""
    m = np.asarray(rotation)
    pitch = math.asin(max(-1.0, min(1.0, -m[2, 0])))
    if abs(m[2, 0]) < 1.0 - 1e-12:
        return math.atan2(m[2, 1], m[2, 2]), pitch, math.atan2(m[1, 0], m[0, 0])
    return 0.0, pitch, math.atan2(-m[0, 1], m[1, 1])


def robosimian() -> str:
    """RoboSimian's URDF from the figures above."""
    urdf = Urdf('robosimian', digits=12)
    chassis = RS_CHASSIS
    to_base = rpy_matrix(CHRONO_TO_BASE_RPY)
    # The chassis' inertia stays in Chrono's axes: the inertial frame is turned over.
    urdf.link('base_link', chassis['mass_kg'], to_base @ chassis['com_m'],
              chassis['inertia_xx'], ((0, 0, 0), box(chassis['box_m'])),
              inertia_xy=chassis['inertia_xy'], inertia_rpy=CHRONO_TO_BASE_RPY)
    for prefix, (mount_xyz, mount_rpy) in RS_MOUNTS.items():
        urdf.joint(f'{prefix}_mount', 'base_link', f'{prefix}_link_0', to_base @ mount_xyz,
                   rpy=matrix_rpy(to_base @ rpy_matrix(mount_rpy)))
        urdf.link(f'{prefix}_link_0')
        for k, parent, xyz, rpy, axis, figures in RS_CHAIN:
            mass, com, inertia_xx, inertia_xy = RS_LINKS[figures]
            urdf.joint(f'{prefix}_joint_{k}', f'{prefix}_link_{parent}', f'{prefix}_link_{k}',
                       xyz, axis, (-RS_LIMIT_RAD, RS_LIMIT_RAD), RS_VELOCITY_LIMIT_RAD_S, rpy=rpy)
            urdf.link(f'{prefix}_link_{k}', mass, com, inertia_xx, inertia_xy=inertia_xy)
        for name, parent, xyz, rpy, figures in RS_FIXED:
            mass, com, inertia_xx, inertia_xy = RS_LINKS[figures]
            parent_link = f'{prefix}_{parent}' if isinstance(parent, str) \
                else f'{prefix}_link_{parent}'
            urdf.joint(f'{prefix}_{name}_joint', parent_link, f'{prefix}_{name}', xyz, rpy=rpy)
            urdf.link(f'{prefix}_{name}', mass, com, inertia_xx, inertia_xy=inertia_xy)
        # Link 7 at zero joint angles, in the base frame: the foot frame undoes it.
        at_zero = to_base @ rpy_matrix(mount_rpy)
        for _k, _parent, _xyz, rpy, _axis, _figures in RS_CHAIN:
            at_zero = at_zero @ rpy_matrix(rpy)
        sole = RS_FOOT_CENTRE_BEYOND_JOINT_7_M + RS_FOOT_RADIUS_M
        urdf.joint(f'{prefix}_foot_joint', f'{prefix}_link_7', f'{prefix}_foot', (sole, 0, 0),
                   rpy=matrix_rpy(at_zero.T))
        urdf.link(f'{prefix}_foot', visual=((0, 0, RS_FOOT_RADIUS_M), sphere(RS_FOOT_RADIUS_M)))
    return urdf.text()


# -- biped -------------------------------------------------------------------------------------

BIPED = {
    'hip_y_m': 0.08,
    'hip_z_m': -0.08,
    'thigh_m': 0.3,
    'shin_m': 0.3,
    'ankle_to_sole_m': 0.05,
}
BIPED_JOINTS = [  # name, axis, limits [rad], velocity limit [rad/s]
    ('hip_yaw', (0, 0, 1), (-0.8, 0.8)),
    ('hip_roll', (1, 0, 0), (-0.6, 0.6)),
    ('hip_pitch', (0, 1, 0), (-1.8, 1.0)),
    ('knee', (0, 1, 0), (0.0, 2.4)),
    ('ankle_pitch', (0, 1, 0), (-1.2, 1.0)),
    ('ankle_roll', (1, 0, 0), (-0.6, 0.6)),
]


def biped() -> str:
    """The biped's URDF."""
    p = BIPED
    urdf = Urdf('biped')
    urdf.link('base_link', 5.0, (0, 0, 0), box_inertia(5.0, (0.15, 0.25, 0.1)),
              ((0, 0, 0), box((0.15, 0.25, 0.1))))
    urdf.joint('torso_joint', 'base_link', 'torso', (0, 0, 0.05))
    urdf.link('torso', 12.0, (0, 0, 0.18), box_inertia(12.0, (0.2, 0.3, 0.36)),
              ((0, 0, 0.18), box((0.2, 0.3, 0.36))))
    l1, l2, sole = p['thigh_m'], p['shin_m'], p['ankle_to_sole_m']
    # (joint origin, link mass, link com, inertia, visual) for each of the six leg joints
    links = [
        ((0, p['hip_y_m'], p['hip_z_m']), 0.5, (0, 0, 0), box_inertia(0.5, (0.06,) * 3), None),
        ((0, 0, 0), 0.5, (0, 0, 0), box_inertia(0.5, (0.06,) * 3), None),
        ((0, 0, 0), 3.0, (0, 0, -l1 / 2), rod_inertia(3.0, l1, 0.045),
         ((0, 0, -l1 / 2), cylinder(l1, 0.045))),
        ((0, 0, -l1), 2.0, (0, 0, -l2 / 2), rod_inertia(2.0, l2, 0.04),
         ((0, 0, -l2 / 2), cylinder(l2, 0.04))),
        ((0, 0, -l2), 0.3, (0, 0, 0), box_inertia(0.3, (0.05,) * 3), None),
        ((0, 0, 0), 0.7, (0.02, 0, -sole / 2), box_inertia(0.7, (0.2, 0.1, sole)),
         ((0.02, 0, -sole / 2), box((0.2, 0.1, sole)))),
    ]
    for side, sign in (('l', 1.0), ('r', -1.0)):
        s = np.array([1.0, sign, 1.0])
        det = sign
        parent = 'base_link'
        for (name, axis, limits), (origin, mass, com, inertia, visual) in zip(
                BIPED_JOINTS, links, strict=True):
            link = f'{side}_{name}_link'
            urdf.joint(f'{side}_{name}', parent, link, s * np.array(origin),
                       det * s * np.array(axis), limits, 6.0)
            vis = None if visual is None else (s * np.array(visual[0]), visual[1])
            urdf.link(link, mass, s * np.array(com), inertia, vis)
            parent = link
        urdf.joint(f'{side}_sole_joint', parent, f'{side}_sole', (0, 0, -sole))
        urdf.link(f'{side}_sole')
    return urdf.text()


def main(root: str = '.') -> int:
    """Write both URDFs under ``root``/config/robots."""
    folder = Path(root) / 'config' / 'robots'
    (folder / 'robosimian.urdf').write_text(robosimian())
    (folder / 'biped.urdf').write_text(biped())
    return 0


if __name__ == '__main__':
    sys.exit(main(*sys.argv[1:]))
