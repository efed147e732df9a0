"""The `robot-hoi` subcommands, one module each, apart from the library: every module here only parses its
arguments and calls library functions; no library module imports this package (import-linter checks it,
`[tool.importlinter]` in pyproject.toml).

Command modules import the library inside their handlers, on purpose: `robot-hoi --help` and argument errors answer
without torch or MuJoCo, in 0.12 s against 1.6 s with torch imported (`python -m robot_hoi.cli --help`, median of 5;
`python -c "import torch"` alone: 1.5 s); tests/test_imports.py keeps --help free of both."""
