"""Summarizers: Trajectories -> Tensor[N, F], batched torch on the data's device."""
