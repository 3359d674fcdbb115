"""The dispatcher process (`fleet dispatcher`, `python -m dispatcher`): it runs the mission's
engine with the forklift agents as its executor (remote.py) and the run's clock as its pacer
(clock.py), hands out forklift ids to agents that claim one (claims.py), follows who is alive
(liveness.py) and picks a mission up after a restart (pickup.py)."""
