"""One forklift's agent process (`fleet agent`, `python -m vehicle_agent`): it plans, commits
and drives the subtasks the dispatcher hands it (agent.py), on the run's clock as it hears it
(clock.py); process.py starts it, claiming a forklift id when it was given none."""
