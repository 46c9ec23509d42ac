"""CANopen (CiA 301) transport for CiA-402 drives: PDO layout, bus load, master."""
