"""Command line of the harness (`progmo-harness`); filled by the harness modules."""


def main() -> int:
    print("progmo-harness: no command yet")
    return 0
