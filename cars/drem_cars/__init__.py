"""drem_cars."""
