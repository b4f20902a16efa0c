"""Reports over a sweep dir: `python -m bayessim_exp.report <sweep dir>` (see build.py)."""
