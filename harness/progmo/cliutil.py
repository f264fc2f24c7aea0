"""One help style for every ``progmo`` subcommand: the Python ones (check, debug, report, bench)
print their help in the layout of the Rust ones (clap): ``Usage:``, ``Arguments:``, ``Options:``,
descriptions kept as written."""

from __future__ import annotations

import argparse
from typing import Any


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """clap's layout: "Usage: ..." and a wider help column."""

    def __init__(self, prog: str, **kw: Any) -> None:
        kw.setdefault("max_help_position", 32)
        kw.setdefault("width", 100)
        super().__init__(prog, **kw)

    def add_usage(self, usage, actions, groups, prefix=None):  # type: ignore[no-untyped-def]
        return super().add_usage(usage, actions, groups, "Usage: " if prefix is None else prefix)


def styled(p: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Give a parser (and its subparsers' future children) the shared section titles."""
    p.formatter_class = HelpFormatter
    p._positionals.title = "Arguments"
    p._optionals.title = "Options"
    return p


def parser(prog: str, description: str, epilog: str | None = None, **kw: Any) -> argparse.ArgumentParser:
    """An ArgumentParser in the shared help style."""
    return styled(argparse.ArgumentParser(prog=prog, description=description, epilog=epilog,
                                          formatter_class=HelpFormatter, **kw))
