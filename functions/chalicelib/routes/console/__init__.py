"""The staff and racer console: server-rendered pages and htmx fragments under /console."""
