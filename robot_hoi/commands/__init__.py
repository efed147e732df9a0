"""The `robot-hoi` subcommands, one module each, apart from the library: every module here only parses its
arguments and calls library functions; no library module imports this package (import-linter checks it,
`[tool.importlinter]` in pyproject.toml)."""
