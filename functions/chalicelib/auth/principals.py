"""Moved to chalicelib.core.principals (below every layer, docs/architecture.md); this name stays only until the
branches that were in flight when it moved have landed. New code imports chalicelib.core.principals."""
from chalicelib.core.principals import *  # noqa: F403
