"""drem_leaderboard: pure race and leaderboard logic (state machine, timing strips, averages, summaries, ranking, CSV).

No I/O and no clock reads: callers pass the server time in and store what comes back.
"""
