"""The joint trajectory a position-controlled robot holds and follows on its own clock.

A follower of /joint_commands (the kinematic simulator, as a ros2_control
joint_trajectory_controller on a robot) holds one trajectory: knots at absolute times [ns], each
with a position per joint and, when the publisher sent them, a velocity per joint. A new message
replaces the held trajectory from its first point's time on; the held points before that time
are kept (ROS 1 joint_trajectory_controller's trajectory replacement, which ros2_control's
follows). A trajectory that starts after it was received starts from the command held at its
receipt: that state is inserted as a knot at the instant of receipt, so the command moves on from
where it was rather than jumping.

:meth:`HeldTrajectory.sample` gives the command at any instant: between two knots with velocities
the cubic Hermite polynomial of their positions and velocities, between knots where one lacks
them the straight line; before the first knot the first knot's position, after the last the last
knot's position (held, at zero velocity). Sampling at a knot's time gives its position exactly
(and its velocity, if it has one).
"""

from __future__ import annotations

import bisect

import numpy as np

from gait_nodes.errors import ParameterError


def hermite(p0: np.ndarray, v0: np.ndarray, p1: np.ndarray, v1: np.ndarray, h_s: float,
            s: float) -> tuple[np.ndarray, np.ndarray]:
    """Cubic Hermite interpolation of one segment: position and velocity at fraction ``s``.

    Args:
        p0: Positions at the start of the segment [rad].
        v0: Velocities at the start [rad/s].
        p1: Positions at the end [rad].
        v1: Velocities at the end [rad/s].
        h_s: Duration of the segment in [s], > 0.
        s: Fraction of the segment, in [0, 1].

    Returns:
        Positions [rad] and velocities [rad/s] at ``s``.
    """
    s2 = s * s
    s3 = s2 * s
    # The Hermite basis h00, h10, h01, h11 and their derivatives in s.
    h00, h10, h01, h11 = 2 * s3 - 3 * s2 + 1, s3 - 2 * s2 + s, 3 * s2 - 2 * s3, s3 - s2
    d00, d10, d11 = 6 * s2 - 6 * s, 3 * s2 - 4 * s + 1, 3 * s2 - 2 * s
    position = h00 * p0 + h01 * p1 + (h10 * h_s) * v0 + (h11 * h_s) * v1
    velocity = (d00 / h_s) * (p0 - p1) + d10 * v0 + d11 * v1
    return position, velocity


class HeldTrajectory:
    """A joint trajectory held by a follower, with the replacement rule of the module docstring.

    Args:
        initial_positions_rad: (J,) the command before any trajectory [rad or m].
    """

    def __init__(self, initial_positions_rad: np.ndarray):
        initial = np.array(initial_positions_rad, dtype=float)
        if initial.ndim != 1 or not np.isfinite(initial).all():
            raise ParameterError(f'initial positions must be a finite vector, got {initial!r}')
        self._initial = initial
        self._zero = np.zeros(len(initial))
        self._times_ns: list[int] = []
        self._positions: list[np.ndarray] = []
        self._velocities: list[np.ndarray | None] = []

    @property
    def joint_count(self) -> int:
        """Number of joints J."""
        return len(self._initial)

    @property
    def times_ns(self) -> tuple[int, ...]:
        """Absolute times of the held knots [ns], increasing."""
        return tuple(self._times_ns)

    @property
    def end_ns(self) -> int | None:
        """Time of the last knot [ns]; None before any trajectory."""
        return self._times_ns[-1] if self._times_ns else None

    def sample(self, t_ns: int) -> tuple[np.ndarray, np.ndarray]:
        """Commanded positions [rad] and velocities [rad/s] at ``t_ns`` (module docstring)."""
        times = self._times_ns
        k = bisect.bisect_right(times, t_ns)
        if k == 0:
            return (self._positions[0] if times else self._initial), self._zero
        if k == len(times):  # at the last knot (its own velocity) or past it (held still)
            velocity = self._velocities[-1] if t_ns == times[-1] else None
            return self._positions[-1], self._zero if velocity is None else velocity
        t0, t1 = times[k - 1], times[k]
        p0, v0 = self._positions[k - 1], self._velocities[k - 1]
        if t_ns == t0 and v0 is not None:
            return p0, v0  # at a knot (every tick, when the knots are on the tick grid)
        p1, v1 = self._positions[k], self._velocities[k]
        h_s = (t1 - t0) * 1e-9
        s = (t_ns - t0) / (t1 - t0)
        if v0 is None or v1 is None:
            return p0 + s * (p1 - p0), (p1 - p0) / h_s
        return hermite(p0, v0, p1, v1, h_s, s)

    def replace(self, times_ns, positions_rad: np.ndarray, velocities_rad_s: np.ndarray | None,
                received_ns: int) -> None:
        """Take a new trajectory from its first knot's time on (module docstring).

        Args:
            times_ns: (N,) absolute knot times [ns], strictly increasing.
            positions_rad: (N, J) positions of every joint.
            velocities_rad_s: (N, J) velocities, or None (positions only: linear).
            received_ns: When the trajectory was received [ns].
        """
        times = [int(t) for t in times_ns]
        positions = np.asarray(positions_rad, dtype=float)
        if not times or positions.shape != (len(times), self.joint_count) \
                or any(b <= a for a, b in zip(times, times[1:], strict=False)):
            raise ParameterError(f'a trajectory needs increasing times and ({len(times)}, '
                                 f'{self.joint_count}) positions, got {positions.shape}')
        first_ns = times[0]
        kept = bisect.bisect_left(self._times_ns, first_ns)
        bridge = None
        if received_ns < first_ns and (kept == 0 or self._times_ns[kept - 1] < received_ns):
            bridge = self.sample(received_ns)  # the command held at receipt
        del self._times_ns[kept:], self._positions[kept:], self._velocities[kept:]
        if bridge is not None:
            self._times_ns.append(int(received_ns))
            self._positions.append(bridge[0])
            self._velocities.append(bridge[1])
        self._times_ns.extend(times)
        self._positions.extend(positions)
        if velocities_rad_s is None:
            self._velocities.extend([None] * len(times))
        else:
            self._velocities.extend(np.asarray(velocities_rad_s, dtype=float))

    def discard_before(self, t_ns: int) -> None:
        """Forget the knots that no sample at ``t_ns`` or later needs.

        The last knot at or before ``t_ns`` stays (it starts the segment of ``t_ns``).
        """
        k = bisect.bisect_right(self._times_ns, t_ns) - 1
        if k > 0:
            del self._times_ns[:k], self._positions[:k], self._velocities[:k]
