"""MuJoCo's own system identification (`mujoco.sysid`) as an inference method: Gauss-Newton least squares of
the real observations against replays of their recorded actions (residual.py, fit.py), turned into a Gaussian
over the parameters (laplace.py)."""
