"""One help style for every ``progmo`` subcommand: the Python ones (check, debug, report, bench)
print their help in the layout of the Rust ones (clap): the description first, then ``Usage:``,
``Arguments:``, ``Options:``, the epilog; descriptions kept as written."""

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


class Parser(argparse.ArgumentParser):
    """An ArgumentParser whose help reads like clap's (description before usage)."""

    def format_help(self) -> str:
        f = self._get_formatter()
        f.add_text(self.description)
        f.add_usage(self.usage, self._actions, self._mutually_exclusive_groups)
        for group in self._action_groups:
            f.start_section(group.title)
            f.add_text(group.description)
            f.add_arguments(group._group_actions)
            f.end_section()
        f.add_text(self.epilog)
        return f.format_help()


def styled(p: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Give a parser (and its subparsers' future children) the shared section titles."""
    p.formatter_class = HelpFormatter
    p._positionals.title = "Arguments"
    p._optionals.title = "Options"
    for a in p._actions:
        if isinstance(a, argparse._HelpAction):
            a.help = "Print help"
    return p


def parser(prog: str, description: str, epilog: str | None = None, **kw: Any) -> argparse.ArgumentParser:
    """An ArgumentParser in the shared help style."""
    return styled(Parser(prog=prog, description=description, epilog=epilog,
                                          formatter_class=HelpFormatter, **kw))
