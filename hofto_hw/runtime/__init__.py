"""The composition root: builds plants, buses, drive groups (and the service) from config.

Application layer: may import every package. ``build`` holds the config-to-object builders,
so drivers/ never reads a whole SystemConfig and the plant is constructed in one place.
"""
