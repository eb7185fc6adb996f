"""Minimisers of chi-square, by name (thesis 6.4 and beyond)."""

from .adam import adam
from .annealing import SCHEDULES, AnnealingOptions, simulated_annealing
from .global_search import global_search
from .levenberg_marquardt import levenberg_marquardt

#: Fit methods by name; ``global`` is the default.
METHODS = {"global": global_search, "lm": levenberg_marquardt, "anneal": simulated_annealing,
           "adam": adam}

__all__ = ["METHODS", "SCHEDULES", "AnnealingOptions", "adam", "global_search",
           "levenberg_marquardt", "simulated_annealing"]
