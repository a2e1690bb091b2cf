"""Sub-commands of the ``slam`` CLI, one module each, each with ``add_arguments(parser)`` and a
run function; :data:`slam.cli.COMMANDS` names them and builds their parsers."""
