"""What a recording says: loss accounting, the safety verifier (independent of the planner), the
work verdict, per-vehicle statistics."""
