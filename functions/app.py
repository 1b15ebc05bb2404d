"""The drem API and web app. This file only wires things together: middleware and one Blueprint per URL area."""
from __future__ import annotations

from chalice import Chalice

from chalicelib import logs
from chalicelib.routes import accounts, health, login, pages

app = Chalice(app_name="drem")
app.register_middleware(logs.request_log_middleware, "http")

for blueprint_module in (pages, health, login, accounts):
    app.register_blueprint(blueprint_module.bp)
