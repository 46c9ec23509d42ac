"""One module per ``hofto-hw`` sub-command: ``configure(parser)`` and ``run(args) -> int``."""
