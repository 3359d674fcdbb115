"""The zenoh runtime, local launcher and deployment: the bus, access control, the router, each
process kind's command line and life (how it starts, stops and fails), child processes, `fleet
run`'s processes, compose settings, and fault tooling (zenoh lives here and in the process
packages, nowhere else in the core)."""
