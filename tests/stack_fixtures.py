"""Fixtures that start real local stacks (moto server subprocess, app over HTTP) for integration and browser tests."""
