"""The bottom layer of the app: what every other layer may name. `errors` (what went wrong, in the user's terms) and
`principals` (who is calling). Imports nothing of chalicelib above it (docs/architecture.md, pyproject.toml
[tool.importlinter])."""
