"""The real-time service and the composition root: ``build`` turns a config into plants,
buses and drive groups (so drivers/ never reads a whole SystemConfig and the plant is
constructed in one place); loop, tick, clocks, real-time setup, control socket, notify.

Application layer: may import drivers/, safety/ and the foundation.
"""
