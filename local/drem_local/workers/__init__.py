"""Background workers `drem up` starts and supervises beside the app server (each its own module and process)."""
