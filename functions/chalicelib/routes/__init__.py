"""One Blueprint per URL area. Every route is declared with `chalicelib.auth.access.route` (who may call it)."""
