"""The control plane: everything of ``hofto-hw run`` that is not the tick, in its own process.

The loop's process runs the loop and nothing else that a client can slow down: the control
socket server, request parsing and validation, motion planning (ruckig moves, taught-path
timing), saving taught paths, sd_notify and the status text live in the control-plane
process (:mod:`~hofto_hw.control_plane.process`), which talks to the loop through one
shared-memory segment (:mod:`~hofto_hw.control_plane.channel`) of fixed-size words, rings
and a state slot. The loop polls it once per tick without waiting
(:class:`~hofto_hw.control_plane.port.LoopPort`): a stop word first, then at most one
request record; a plan is streamed into a ring of trajectory rows the tick consumes, and a
row that is not there yet is "not yet" (the reference ramps down), never a wait.
"""
