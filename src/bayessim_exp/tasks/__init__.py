"""Tasks: a MuJoCo model with observations, actions, reward, reset and parameters to infer."""
