"""SimOpt (Chebotar et al. 2019): a Gaussian over simulation parameters, moved by REPS towards parameters
whose simulated roll-outs of the policy match the real ones (discrepancy.py, reps.py, search.py)."""
