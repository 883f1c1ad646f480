"""Sub-commands of the ``vibroscope`` CLI, one module each (``add_parser(subparsers)``)."""
