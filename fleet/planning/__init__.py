"""One vehicle on a grid: its body, its motion (seed 000's manners and velocity planner), the
improved hybrid A* and the space-time reservation table it plans against. No warehouse, no
network."""
