"""Kinematic simulation and the full-model ZMP monitor (no ROS import).

:mod:`gait_nodes.sim.kinematics` integrates joint commands as position-controlled actuators and
places the floating base on the stance feet; :mod:`gait_nodes.sim.zmp_monitor` computes the
multi-body ZMP, the COM and the stability margin of the resulting motion.
"""
