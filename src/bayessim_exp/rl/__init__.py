"""RL in the loop (torchrl PPO); `none` runs BayesSim rounds without a policy to train."""
