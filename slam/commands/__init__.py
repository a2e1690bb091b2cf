"""Sub-commands of the ``slam`` CLI, one module each, each with ``register(subparsers)``."""
