"""Real trajectories read from robot logs in common formats: LeRobot datasets (lerobot.py) and CSV tables
(csv_table.py), mapped to the task's observations and actions (mapping.py) and resampled to its control rate
(resample.py)."""
