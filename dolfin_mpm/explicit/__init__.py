"""The explicit MPM solver: the step's stages, the state a run carries, its options and run loop."""
