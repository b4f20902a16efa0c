"""Batched MuJoCo simulation with per-environment parameters."""
