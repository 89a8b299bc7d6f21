"""CLI subcommands. Each module here defines `register(subparsers)` and is discovered by
`mop.cli`; heavy imports belong inside the command's run function, not at module level."""


def count(number: int, noun: str) -> str:
    """"1 channel", "5 channels", "0 frames": a number with its noun, singular when it is one."""
    return f"{number} {noun}" if number == 1 else f"{number} {noun}s"
