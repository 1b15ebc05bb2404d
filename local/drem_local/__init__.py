"""The local event stack: durable moto server, resource bootstrap, app server and the `drem` CLI."""
