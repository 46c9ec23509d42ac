"""CiA-402 drive profile: process-image layout, state machine, units, codes, drive layer.

Shared by every transport (in-process simulator, EtherCAT, CANopen). Raw values (counts,
per-mille) live only in this package and the transports; the drive layer hands SI values up.
"""
