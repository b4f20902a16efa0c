"""Comparing results.json of two runs: everything but wall time must match."""


def without_seconds(obj):
    """results.json with every wall-time field dropped (all that may differ between two equal runs)."""
    if isinstance(obj, dict):
        return {k: without_seconds(v) for k, v in obj.items() if k != "seconds"}
    if isinstance(obj, list):
        return [without_seconds(v) for v in obj]
    return obj
