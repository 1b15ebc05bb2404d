"""Moved to chalicelib.core.errors (below every layer, docs/architecture.md); this name stays only until the branches
that were in flight when it moved have landed. New code imports chalicelib.core.errors."""
from chalicelib.core.errors import *  # noqa: F403
