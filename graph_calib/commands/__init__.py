"""One module per command (``<name>_cmd.py``) with ``add_arguments(parser)`` and ``run(args)``."""
