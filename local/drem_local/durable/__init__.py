"""A moto server that keeps its state across restarts and `kill -9`.

moto itself keeps everything in memory. This package runs moto's own WSGI app behind a middleware that writes
every state-changing request to an fsynced journal before moto sees it, pickles the backends to per-service
snapshots now and then, and on start loads the snapshots and replays the journal tail.
Run it with `python -m drem_local.durable --state-dir DIR --port N`.
"""
from __future__ import annotations
