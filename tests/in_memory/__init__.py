"""In-memory implementations of the app's storage ports, for the fast domain tier (tests/domain).

Each class copies the behaviour of the DynamoDB adapter it stands for, on every point the domain relies on
(conditional writes and their Conflict, not-found, what a read returns after a write), and names that adapter.
tests/unit/test_store_contracts.py runs the same assertions against both, so the two cannot drift apart.
"""
