"""linknet benchmarks: work-precision against peers (work_precision.py) and the stress suite (stress.py)."""
