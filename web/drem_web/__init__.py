"""drem_web."""
