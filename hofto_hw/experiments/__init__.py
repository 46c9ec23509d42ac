"""Experiments that reproduce the paper's evaluations on the simulated arm."""
