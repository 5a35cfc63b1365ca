#!/usr/bin/env python3
"""Whole-body IK per-tick solve time, gait_nodes against pink on the same targets.

    python bench/ik.py [--ticks 2000] [--reps 3] [--robots go2,robosimian,talos]
                       [--tolerance 1e-6] [--no-pink]

For each robot a 200 Hz walking-like sequence of targets is built: the COM sways sideways and
drifts forward, the body yaw turns slowly, and one foot at a time follows a fallback swing (lift
and forward step) while the others stand. Every tick is solved warm-started from the previous
ticks' solutions, as the whole_body_ik node does (gait_nodes: extrapolated from the last three by
``WholeBodyIkSolver.warm_start``; pink: from the last one):

* gait_nodes: :class:`gait_nodes.robot.whole_body_ik.WholeBodyIkSolver` (full model; joints the
  IK does not move held at the posture).
* pink (``pin-pink`` with the ``daqp`` QP solver): the same model reduced to the same IK joints
  (``pin.buildReducedModel``), a FrameTask per foot (orientation cost 1 for flat feet, 0 for
  point feet), a ComTask, a FrameTask holding the base orientation; ``solve_ik`` with
  ``dt = 1`` and integration repeated until the same tolerances are met (at most 50 steps).

Printed per robot and solver: per-tick time median and p99 [ms], iterations, ticks that reached
the tolerance, and the worst foot and COM errors checked by an independent Pinocchio FK; then the
pink/ours ratio. The sequence is run ``--reps`` times (same deterministic ticks): "raw" pools every
run; "min" takes each tick's fastest run, which removes the OS preemptions (a few ms each) that a
loaded machine adds to any Python loop, so that p99 shows the solver's own tail.
Targets (issue 4): <= 0.5 ms for 12 joints, <= 1 ms for 28+, faster than pink.
Figures only: nothing is asserted.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

import pinocchio as pin  # noqa: E402

from gait_nodes.contract import Swing  # noqa: E402
from gait_nodes.errors import ConfigError  # noqa: E402
from gait_nodes.robot.model import load_robot_model, yaw_rotation  # noqa: E402
from gait_nodes.robot.whole_body_ik import (  # noqa: E402
    IkSettings,
    IkTargets,
    WholeBodyIkSolver,
    fallback_swing_pose,
    nominal_configuration,
)

RATE_HZ = 200.0
TARGET_MS = {12: 0.5, 28: 1.0}


def walking_targets(robot, q0, ticks: int) -> list[IkTargets]:
    """A 200 Hz sequence: COM sway and drift, slow yaw, one foot at a time swinging."""
    feet0, yaws0 = robot.foot_poses(q0)
    com0 = robot.com(q0)
    size = robot.description.body_height_m
    step = 0.25 * robot.description.reach.max_step_length_m
    swing_s, count = 0.8, len(feet0)
    feet = feet0.copy()
    targets = []
    for k in range(ticks):
        t = k / RATE_HZ
        yaw = 0.1 * math.sin(2 * math.pi * t / 8.0)
        rotation = yaw_rotation(yaw)
        phase, cycle = math.modf(t / swing_s)
        foot = int(cycle) % count
        start = feet[foot].copy()
        advance = np.array([step * (int(cycle) // count + 1), 0.0, 0.0])
        end = com0 * [1, 1, 0] + rotation @ (feet0[foot] - com0 * [1, 1, 0]) + advance
        end[2] = feet0[foot][2]
        swing = Swing(robot.foot_names[foot], 0.0, swing_s, start, end, yaws0[foot] + yaw,
                      yaws0[foot] + yaw)
        current = feet.copy()
        current[foot], _ = fallback_swing_pose(swing, phase * swing_s, 0.2 * size)
        if k + 1 < ticks and int((k + 1) / RATE_HZ / swing_s) != int(cycle):
            feet[foot] = end
        com = com0 + [step * t / (swing_s * count),
                      0.04 * size * math.sin(2 * math.pi * t / (swing_s * count)), 0.0]
        targets.append(IkTargets(current, yaws0 + yaw, yaw, com_in_world=com))
    return targets


def independent_errors(robot, q, targets) -> tuple[float, float]:
    """Worst foot position error and COM error of ``q`` [m] by a fresh Pinocchio FK."""
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    feet = max(np.linalg.norm(data.oMf[f].translation - [0, 0, robot.foot_frame_height_m]
                              - targets.feet_in_world[k])
               for k, f in enumerate(robot.foot_frame_ids))
    com = np.linalg.norm(pin.centerOfMass(robot.model, data, q) - targets.com_in_world)
    return float(feet), float(com)


def run_ours(robot, q0, sequence, tolerance):
    """Solve the sequence with gait_nodes' solver: times [ms], iterations, on target, worst."""
    solver = WholeBodyIkSolver(robot, IkSettings(
        max_iterations=50, position_tolerance_m=tolerance, orientation_tolerance_rad=tolerance,
        com_tolerance_m=tolerance))
    solutions = [q0]
    times, iterations, converged, worst = [], [], 0, [0.0, 0.0]
    for targets in sequence:
        start = time.perf_counter_ns()
        result = solver.solve(targets, solver.warm_start(solutions))
        times.append((time.perf_counter_ns() - start) * 1e-6)
        q = result.q
        solutions = [*solutions[-2:], q]
        iterations.append(result.iterations)
        converged += result.converged
        errors = independent_errors(robot, q, targets)
        worst = [max(worst[0], errors[0]), max(worst[1], errors[1])]
    return times, iterations, converged, worst


class PinkRunner:
    """pink on the model reduced to the IK joints, same tasks, same tolerance."""

    def __init__(self, robot, q0, tolerance):
        import pink
        from pink.tasks import ComTask, FrameTask

        self.pink, self.robot, self.tolerance = pink, robot, tolerance
        model = robot.model
        keep = set(robot.ik_joint_names)
        locked = [model.getJointId(n) for n in robot.joint_names if n not in keep]
        self.model = pin.buildReducedModel(model, locked, q0) if locked else model
        self.data = self.model.createData()
        self.q_index = np.concatenate([np.arange(7), [
            model.joints[model.getJointId(n)].idx_q for n in model.names[2:]
            if n in keep]]).astype(int)
        self.full_q = np.array(q0)
        orient = 1.0 if robot.foot_orientation == 'yaw' else 0.0
        self.feet = [FrameTask(model.frames[f].name, position_cost=1.0, orientation_cost=orient)
                     for f in robot.foot_frame_ids]
        self.com = ComTask(cost=1.0)
        self.base = FrameTask(robot.description.base_frame, position_cost=0.0,
                              orientation_cost=1.0)
        self.configuration = pink.Configuration(self.model, self.data, q0[self.q_index])
        self.offsets = robot.foot_rotation_offsets
        self.foot_ids = [self.model.getFrameId(model.frames[f].name)
                         for f in robot.foot_frame_ids]

    def solve(self, targets):
        """Iterate pink until the tolerances hold: (steps, reached)."""
        for k, task in enumerate(self.feet):
            target = pin.SE3(yaw_rotation(targets.foot_yaws_rad[k]) @ self.offsets[k],
                             targets.feet_in_world[k] + [0, 0, self.robot.foot_frame_height_m])
            task.set_target(target)
        self.com.set_target(np.asarray(targets.com_in_world))
        self.base.set_target(pin.SE3(yaw_rotation(targets.base_yaw_rad), np.zeros(3)))
        tasks = [*self.feet, self.com, self.base]
        orient = self.robot.foot_orientation == 'yaw'
        for iteration in range(51):
            data = self.configuration.data
            q = self.configuration.q
            com = pin.centerOfMass(self.model, data, q, False)
            foot_error = max(np.linalg.norm(data.oMf[f].translation - [
                0, 0, self.robot.foot_frame_height_m] - targets.feet_in_world[k])
                for k, f in enumerate(self.foot_ids))
            rot_error = max(np.linalg.norm(pin.log3(
                (yaw_rotation(targets.foot_yaws_rad[k]) @ self.offsets[k]).T
                @ data.oMf[f].rotation)) for k, f in enumerate(self.foot_ids)) if orient else 0
            if (foot_error <= self.tolerance and rot_error <= self.tolerance
                    and np.linalg.norm(com - targets.com_in_world) <= self.tolerance) \
                    or iteration == 50:
                return iteration, iteration < 50
            velocity = self.pink.solve_ik(self.configuration, tasks, 1.0, solver='daqp',
                                          safety_break=False)
            self.configuration.integrate_inplace(velocity, 1.0)
        return 50, False

    def full_configuration(self):
        """The pink configuration written back into the full model's ``q``."""
        q = self.full_q.copy()
        q[self.q_index] = self.configuration.q
        return q


def run_pink(robot, q0, sequence, tolerance):
    """Solve the sequence with pink: times [ms], iterations, on target, worst errors."""
    runner = PinkRunner(robot, q0, tolerance)
    times, iterations, converged, worst = [], [], 0, [0.0, 0.0]
    for targets in sequence:
        start = time.perf_counter_ns()
        count, ok = runner.solve(targets)
        times.append((time.perf_counter_ns() - start) * 1e-6)
        iterations.append(count)
        converged += ok
        errors = independent_errors(robot, runner.full_configuration(), targets)
        worst = [max(worst[0], errors[0]), max(worst[1], errors[1])]
    return times, iterations, converged, worst


def measure(label, run, robot, q0, sequence, tolerance, reps):
    """Run ``reps`` times, print the figures, return the median of per-tick minima [ms]."""
    runs = [run(robot, q0, sequence, tolerance) for _ in range(reps)]
    times = np.array([r[0] for r in runs])
    _, iterations, converged, worst = runs[0]
    fastest = times.min(axis=0)
    median, p99 = np.median(fastest), np.percentile(fastest, 99)
    print(f'  {label:<11} min: median {median:6.3f} ms  p99 {p99:6.3f} ms | raw: median '
          f'{np.median(times):6.3f} ms  p99 {np.percentile(times, 99):6.3f} ms | iterations '
          f'{np.mean(iterations):4.2f} (max {max(iterations)})  on target '
          f'{converged}/{len(sequence)}  worst foot {worst[0] * 1e3:.1e} mm  '
          f'COM {worst[1] * 1e3:.1e} mm')
    return median


def main(argv=None) -> int:
    """Parse the options and print the figures for each robot."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--ticks', type=int, default=2000, help='ticks per robot (200 Hz)')
    parser.add_argument('--reps', type=int, default=3, help='runs of the whole sequence')
    parser.add_argument('--robots', default='go2,robosimian,talos')
    parser.add_argument('--tolerance', type=float, default=1e-6,
                        help='foot, orientation and COM tolerance for both solvers [m, rad]')
    parser.add_argument('--no-pink', action='store_true')
    args = parser.parse_args(argv)
    pink_ok = not args.no_pink
    if pink_ok:
        try:
            import pink  # noqa: F401
        except ImportError:
            print('pink is not installed (pip install pin-pink daqp): gait_nodes figures only')
            pink_ok = False
    for name in args.robots.split(','):
        try:
            robot = load_robot_model(name)
        except ConfigError as exc:
            print(f'{name}: skipped ({exc})')
            continue
        q0 = nominal_configuration(robot)
        sequence = walking_targets(robot, q0, args.ticks)
        joints = len(robot.joint_names)
        target = TARGET_MS[12] if joints <= 12 else TARGET_MS[28]
        print(f'{name}: {joints} joints ({len(robot.ik_joint_names)} moved by the IK), '
              f'{args.ticks} ticks, tolerance {args.tolerance:g}, target <= {target} ms')
        ours = measure('gait_nodes', run_ours, robot, q0, sequence, args.tolerance, args.reps)
        if pink_ok:
            theirs = measure('pink', run_pink, robot, q0, sequence, args.tolerance, args.reps)
            print(f'  pink / gait_nodes median time: {theirs / ours:.1f}x')
    return 0


if __name__ == '__main__':
    sys.exit(main())
