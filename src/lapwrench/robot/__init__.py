"""Robot description, Pinocchio model and per-tick kinematics."""
