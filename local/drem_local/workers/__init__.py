"""Background worker processes `drem up` runs beside the app server (each in its own module)."""
