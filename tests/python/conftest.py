"""Collection order for `harness/test.sh` (pytest-xdist, --dist loadfile: files are handed to the
workers in collection order). The files whose tests wait for a build that runs beside pytest (the
Rust binary of cargo test's build, the C++ anchor) come last, so no worker sits idle waiting
while other files could run."""

from __future__ import annotations

#: files whose first test waits for a background build (harness/test.sh), last in this order
WAITING = ("test_bench.py", "test_bench_page.py", "test_stdout.py")


def pytest_collection_modifyitems(session, config, items):
    def rank(item) -> int:
        name = item.path.name
        return WAITING.index(name) + 1 if name in WAITING else 0

    items.sort(key=rank)  # stable: the order within each group is unchanged
