"""Sub-commands of the ``aslm`` CLI, one module each with ``add_parser(subparsers)``."""
