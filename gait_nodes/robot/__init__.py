"""Robot descriptions (URDF + robot YAML), Pinocchio models and inverse kinematics."""
