"""drem's live server: pushes the public pages' live regions (big-screen leaderboard, stream overlay) to every viewer
over server-sent events, and serves the board/overlay JSON polls from memory. See server.py and docs/architecture.md.
"""
