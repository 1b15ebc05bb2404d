"""drem_sim."""
