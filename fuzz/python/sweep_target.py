"""Coverage-guided fuzzing of sweep files (atheris): ``progmo sweep``'s reading of a sweep file and
its sample generation (the body: ``sweep_body.one_input``). Not part of the package.

    .venv/bin/python -m pip install atheris        # once (PyPI)
    .venv/bin/python fuzz/python/sweep_target.py fuzz/corpus/sweep harness/progmo/references/sweeps \\
        -dict=fuzz/dicts/sweep.dict -runs=10000000 -max_len=8192 -timeout=10 -rss_limit_mb=2048 \\
        -print_final_stats=1

One process (the machine is shared). An exception other than the documented ones, or a timeout,
is a crash: libFuzzer writes the input as ./crash-* (./timeout-*); reproduce with
``.venv/bin/python fuzz/python/sweep_target.py FILE``. The bounded deterministic pass that CI runs
is tests/python/test_fuzz_sweep.py.
"""

import sys
from pathlib import Path

import atheris

sys.path.insert(0, str(Path(__file__).resolve().parent))

with atheris.instrument_imports():
    import progmo.sweep  # noqa: F401  (instrumented: coverage guides the fuzzer through it)
    import sweep_body

FOLDER = sweep_body.folder()


def test_one_input(data: bytes) -> None:
    sweep_body.one_input(data, FOLDER)


if __name__ == "__main__":
    sweep_body.base()  # load the scene before fuzzing starts
    atheris.Setup(sys.argv, test_one_input)
    atheris.Fuzz()
