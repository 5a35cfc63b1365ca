"""Write config/robots/robosimian.urdf and config/robots/biped.urdf (run from the repository root).

Both robots are approximations made for gait_nodes; the numbers are chosen here, in one place:

robosimian
    A RoboSimian-like quadruped (thesis 000 sections II.C-D, III.A): a 0.9 x 0.6 x 0.2 m chassis
    of 40 kg and four identical 7-DOF limbs of 15 kg each (limbs 60 % of the 100 kg total). Each
    limb: shoulder roll (x) and pitch (y) at one point, a 0.42 m thigh, knee pitch (y), a 0.42 m
    shin, a spherical wrist (twist z, pitch y, roll x) at one point, then the 7th joint (foot
    yaw, z, ignored for walking) and a sole 0.12 m below the wrist centre. The joints of all
    limbs are at the same angles for mirror-image poses: the left and rear limbs are the
    front-right limb reflected in the base's x-z and y-z planes (the thesis computes every limb
    with the front-right solution and mirrored coordinates).
biped
    A small humanoid: 31 kg, pelvis and torso, two 6-DOF legs (hip yaw, roll, pitch, knee,
    ankle pitch, roll) with 0.3 m thigh and shin, flat feet with the sole frame 0.05 m below
    the ankle.

Every link frame is parallel to the base at the zero configuration, so that a reflection only
changes signs of positions and axes.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

TWO_PI = 2.0 * math.pi


def _fmt(values) -> str:
    return ' '.join(f'{v:.6g}' for v in values)


def box_inertia(mass, size):
    x, y, z = size
    return np.array([y * y + z * z, x * x + z * z, x * x + y * y]) * mass / 12.0


def rod_inertia(mass, length, radius):
    """Cylinder along z."""
    side = mass * (3 * radius ** 2 + length ** 2) / 12.0
    return np.array([side, side, 0.5 * mass * radius ** 2])


class Urdf:
    def __init__(self, name):
        self.lines = ['<?xml version="1.0"?>', f'<robot name="{name}">']

    def link(self, name, mass=None, com=(0, 0, 0), inertia=(0, 0, 0), visual=None):
        self.lines.append(f'  <link name="{name}">')
        if mass is not None:
            ixx, iyy, izz = inertia
            self.lines += [
                '    <inertial>',
                f'      <origin xyz="{_fmt(com)}" rpy="0 0 0"/>',
                f'      <mass value="{mass:.6g}"/>',
                f'      <inertia ixx="{ixx:.6g}" ixy="0" ixz="0" iyy="{iyy:.6g}" iyz="0" '
                f'izz="{izz:.6g}"/>',
                '    </inertial>']
        if visual is not None:
            origin, geometry = visual
            self.lines += [
                '    <visual>',
                f'      <origin xyz="{_fmt(origin)}" rpy="0 0 0"/>',
                f'      <geometry>{geometry}</geometry>',
                '    </visual>']
        self.lines.append('  </link>')

    def joint(self, name, parent, child, xyz, axis=None, limits=None, velocity=None):
        kind = 'fixed' if axis is None else 'revolute'
        self.lines += [
            f'  <joint name="{name}" type="{kind}">',
            f'    <parent link="{parent}"/>',
            f'    <child link="{child}"/>',
            f'    <origin xyz="{_fmt(xyz)}" rpy="0 0 0"/>']
        if axis is not None:
            lower, upper = limits
            self.lines += [
                f'    <axis xyz="{_fmt(axis)}"/>',
                f'    <limit lower="{lower:.6g}" upper="{upper:.6g}" effort="500" '
                f'velocity="{velocity:.6g}"/>']
        self.lines.append('  </joint>')

    def text(self):
        return '\n'.join(self.lines + ['</robot>', ''])


def cylinder(length, radius):
    return f'<cylinder length="{length:.6g}" radius="{radius:.6g}"/>'


def box(size):
    return f'<box size="{_fmt(size)}"/>'


def sphere(radius):
    return f'<sphere radius="{radius:.6g}"/>'


# -- robosimian --------------------------------------------------------------------------------

ROBOSIMIAN = {
    'body_size_m': (0.9, 0.6, 0.2),
    'body_mass_kg': 40.0,
    'shoulder_fr_m': (0.4, -0.25, 0.0),
    'thigh_m': 0.42,
    'shin_m': 0.42,
    'wrist_to_yaw_joint_m': 0.05,
    'wrist_to_sole_m': 0.12,
    'foot_radius_m': 0.055,
    # link masses [kg]: shoulder, thigh, shin, wrist 1, wrist 2, hand, foot -> 15 kg per limb
    'masses_kg': (2.0, 5.0, 4.0, 1.5, 1.0, 1.0, 0.5),
    'velocity_limit_rad_s': 1.0,
}
# Limb corners: name -> (prefix, reflection of the front-right limb).
LIMBS = {'front_left': ('fl', (1, -1, 1)), 'front_right': ('fr', (1, 1, 1)),
         'rear_left': ('rl', (-1, -1, 1)), 'rear_right': ('rr', (-1, 1, 1))}
# Joint limits [rad]: wide for the roll/pitch/twist joints (room for every IK family), the knee
# stops before the shin hits the thigh.
ROBOSIMIAN_LIMITS = [(-TWO_PI, TWO_PI), (-TWO_PI, TWO_PI), (-2.8, 2.8), (-TWO_PI, TWO_PI),
                     (-TWO_PI, TWO_PI), (-TWO_PI, TWO_PI), (-TWO_PI, TWO_PI)]


def robosimian() -> str:
    p = ROBOSIMIAN
    urdf = Urdf('robosimian')
    body = p['body_size_m']
    urdf.link('base_link', p['body_mass_kg'], (0, 0, 0), box_inertia(p['body_mass_kg'], body),
              ((0, 0, 0), box(body)))
    l1, l2 = p['thigh_m'], p['shin_m']
    d7, sole = p['wrist_to_yaw_joint_m'], p['wrist_to_sole_m']
    m = p['masses_kg']
    # Front-right limb: (joint origin in parent, axis, link mass, link com, inertia, visual)
    chain = [
        ((0, 0, 0), (1, 0, 0), m[0], (0, 0, 0), box_inertia(m[0], (0.12, 0.12, 0.12)),
         ((0, 0, 0), sphere(0.07))),
        ((0, 0, 0), (0, 1, 0), m[1], (0, 0, -l1 / 2), rod_inertia(m[1], l1, 0.05),
         ((0, 0, -l1 / 2), cylinder(l1, 0.05))),
        ((0, 0, -l1), (0, 1, 0), m[2], (0, 0, -l2 / 2), rod_inertia(m[2], l2, 0.045),
         ((0, 0, -l2 / 2), cylinder(l2, 0.045))),
        ((0, 0, -l2), (0, 0, 1), m[3], (0, 0, 0), box_inertia(m[3], (0.08, 0.08, 0.08)),
         ((0, 0, 0), sphere(0.05))),
        ((0, 0, 0), (0, 1, 0), m[4], (0, 0, 0), box_inertia(m[4], (0.07, 0.07, 0.07)), None),
        ((0, 0, 0), (1, 0, 0), m[5], (0, 0, -d7 / 2), rod_inertia(m[5], d7, 0.04),
         ((0, 0, -d7 / 2), cylinder(d7, 0.04))),
        ((0, 0, -d7), (0, 0, 1), m[6], (0, 0, -(sole - d7) / 2),
         rod_inertia(m[6], sole - d7, p['foot_radius_m']),
         ((0, 0, -(sole - d7) / 2), cylinder(sole - d7, p['foot_radius_m']))),
    ]
    for _foot, (prefix, reflection) in LIMBS.items():
        s = np.array(reflection, dtype=float)
        det = float(np.prod(s))
        parent = 'base_link'
        for k, (origin, axis, mass, com, inertia, visual) in enumerate(chain, start=1):
            if k == 1:
                origin = p['shoulder_fr_m']
            link = f'{prefix}_link_{k}'
            # A revolute axis is a pseudo-vector: under a reflection S it becomes det(S) S a,
            # so the same joint angle gives the mirror-image pose.
            urdf.joint(f'{prefix}_joint_{k}', parent, link, s * origin, det * s * np.array(axis),
                       ROBOSIMIAN_LIMITS[k - 1], p['velocity_limit_rad_s'])
            vis = None if visual is None else (s * visual[0], visual[1])
            urdf.link(link, mass, s * np.array(com), inertia, vis)
            parent = link
        urdf.joint(f'{prefix}_foot_joint', parent, f'{prefix}_foot', (0, 0, -(sole - d7)))
        urdf.link(f'{prefix}_foot')
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
    folder = Path(root) / 'config' / 'robots'
    (folder / 'robosimian.urdf').write_text(robosimian())
    (folder / 'biped.urdf').write_text(biped())
    return 0


if __name__ == '__main__':
    sys.exit(main(*sys.argv[1:]))
