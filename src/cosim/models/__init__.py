"""Built-in Python co-simulation units (Panda arm, trajectory, dynamics, planner)."""
