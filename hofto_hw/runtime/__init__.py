"""The real-time service: composition root, loop, tick, clocks, real-time setup, control.

Application layer: may import drivers/, safety/ and the foundation.
"""
