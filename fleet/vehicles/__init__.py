"""Kinds of vehicle: what a vehicle kind is (`kind`: its motion model, its planner, its conflict
policy), seed 000's forklift as the first one (`forklift`), and the names a layout's `[vehicle]
kind` may give (`registry`).

A wing of its own, between the warehouse and the planning code (world, wire -> vehicles ->
planning): the layout checks its poses and stations with the kind it names, and everything
above (mission, processes, analysis) asks the kind instead of importing seed 000's manners and
planner. The planning wing keeps the pieces a kind is built from; a new kind (seeds 002 and
004) adds its module here and its name to the registry."""
