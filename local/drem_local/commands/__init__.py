"""drem subcommands."""
