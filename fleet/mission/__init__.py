"""The run of one mission, the same in one process or many: what the mission is, the work its
kind is made of, the engine's decision loop, the seam to the executors and pacers, faults and
the freeze cascade, the mission record."""
