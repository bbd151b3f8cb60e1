"""Robustness campaigns (`dcts sweep`): many samples of a spec's scenario and controller values,
run with the spec's compiled C controller on a distributed engine, and their report.

It uses spec, sim, analysis and codegen; nothing there uses it.
"""

from .document import Campaign, load_campaign, load_campaign_text
from .optimize import tune
from .sweep import SweepOptions, SweepResult, sweep

__all__ = ["Campaign", "SweepOptions", "SweepResult", "load_campaign", "load_campaign_text", "sweep", "tune"]
