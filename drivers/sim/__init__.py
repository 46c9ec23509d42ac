"""Simulation: the true arm (Plant), external-torque scenarios, emulated drives and buses."""

from drivers.sim.plant import Plant, perturbed_model
from drivers.sim.scenarios import ExternalTorque

__all__ = ["ExternalTorque", "Plant", "perturbed_model"]
