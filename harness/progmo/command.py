"""The ``progmo`` command of the Python package: every subcommand of the Rust ``progmo`` binary.

``solve``, ``validate``, ``export`` and ``--help`` run the Rust command line in this process
(``progmo::cli::run`` through the binding; the bundled scenes are found by name); ``check``,
``debug`` and ``report`` run the harness (``progmo.cli``), ``sweep`` the tolerance sweeps
(``progmo.sweep``), ``bench`` the benchmarks (``progmo.bench.main``), ``corpus`` the robot-file corpus
(``progmo.corpus``). Exit codes are those of the subcommand (``progmo --help``).
"""

from __future__ import annotations

import os
import sys

HARNESS = ("check", "debug", "report")


def main(argv: list[str] | None = None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    from ._stdio import run  # standard output as the Rust commands treat it (exit 3, 141, 130)

    if args and args[0] in HARNESS:
        from .cli import main as harness_main

        return run(lambda: harness_main(args), f"progmo {args[0]}")
    if args and args[0] == "sweep":
        from .sweep import main as sweep_main

        return run(lambda: sweep_main(args[1:]), "progmo sweep")
    if args and args[0] == "corpus":
        from .corpus import main as corpus_main

        return run(lambda: corpus_main(args[1:]), "progmo corpus")
    if args and args[0] == "bench":
        from .bench.main import main as bench_main

        return run(lambda: bench_main(args[1:]), "progmo bench")
    from . import _core, data
    from ._stdio import sanitize_std_fds

    sanitize_std_fds()
    os.environ.setdefault("PROGMO_REFERENCES", str(data.references()))
    sys.stdout.flush()
    sys.stderr.flush()
    return int(_core.cli(["progmo", *args]))


if __name__ == "__main__":
    sys.exit(main())
