"""Vehicle parts: each has run(*inputs) -> outputs and optionally shutdown()."""
