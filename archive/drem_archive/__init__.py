"""Vetting hostile archives and folders: the one set of member-name and member-kind rules used by the app (model
uploads, league and event exports: chalicelib.formats), the car (drem_cars.archive) and the trainer
(drem_sim.learn.package). Standard library only, and it imports nothing else of drem, so every one of them may use it
(pyproject.toml [tool.importlinter]); `drem build` vendors it into the Lambda bundle."""
