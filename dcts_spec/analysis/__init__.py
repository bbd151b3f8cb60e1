"""What a simulation run shows: derived time series, summary metrics, plots and comparisons.

`series` (errors, energies, paths for all samples at once), `metrics` (summary.json), `run` (a run
with everything derived from it), `plots`, `compare` (tables and overlays), `outputs` (output
directories written all or nothing), `simulate` (a whole run from Python).
"""
