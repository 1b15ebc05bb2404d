"""drem_leaderboard."""
