"""Test order for `--dist loadfile` (harness/test.sh hands pytest-xdist one file per worker, in the
collection's order): the long files that come late in the alphabet go first, so the run does not end
on one worker's last long file with the other core idle (fresh clone at 44a11d0: the last two
minutes ran at about 50 % of the 2 cores). Within a file, and among the other files, the order is
unchanged."""

from __future__ import annotations

import pytest

#: the longest files after test_stdout.py in the alphabet (`--durations` of a fresh-clone run:
#: test_wheel 84 s, test_sweep about 60 s, test_sweep_ray about 35 s, with set-up and teardown)
LONG_FIRST = ("test_wheel.py", "test_sweep.py", "test_sweep_ray.py")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    rank = {name: k for k, name in enumerate(LONG_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))
