"""The fleet's decisions: seed 000's Algorithm 1 with its five strategies, the preliminary A*, and
the MLP correction (torch lives here and nowhere else in the core)."""
