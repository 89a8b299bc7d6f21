"""CLI subcommands. Each module here defines `register(subparsers)` and is discovered by
`mop.cli`; heavy imports belong inside the command's run function, not at module level."""
