"""The fleet's decisions: the dispatch-policy seam the engine decides through, seed 000's
Algorithm 1 with its five strategies as its first policy, the preliminary A*, and the MLP
correction (torch lives here and nowhere else in the core)."""
