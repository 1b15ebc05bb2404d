"""drem_infra."""
