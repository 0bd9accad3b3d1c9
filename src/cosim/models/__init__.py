"""Built-in Python co-simulation units (Panda arm, trajectory, dynamics, planner).

Offers: the built-in Python units (``trajectory``, ``panda_exudyn``, ``panda_inverse_dynamics``, ``planner``, ...) and the
Panda's viewer.
"""
