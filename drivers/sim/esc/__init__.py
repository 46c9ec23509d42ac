"""Emulated EtherCAT slaves: a software ESC per drive, served on a network interface.

``description`` (what a slave is), ``sii`` (its EEPROM image), ``esc`` (register space, AL,
SyncManagers, FMMUs, mailbox), ``coe`` (SDO server), ``pdo_map`` (PDO mapping -> copy
plans), ``datagram`` (frames and working counters), ``network`` (the line of slaves with
the emulated drives, the packet loop and the control channel), ``veth`` (veth pairs).
Built from a config by :func:`hofto_hw.runtime.build.build_emulated_network`.
See docs/ethercat_emulator.md.
"""
