"""Shared pytest fixtures."""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Iterator

import pytest
from fakefixtures import board, fake  # noqa: F401  (fixtures, found by pytest by name)
from hypothesis import settings
from simfixtures import boards_for, sim_board  # noqa: F401  (the fixture, found by pytest by name)

# Hypothesis's 200 ms per-example deadline judges the machine's load, not the code: with
# other work on the cores an example can take longer, and the test fails as "flaky".
settings.register_profile("dev", deadline=None)
# Under CI=true (which CI services such as GitHub Actions and GitLab CI set; .ci/run does not set
# it itself) the same examples are drawn every run, so that a verdict never depends on the draw;
# a developer's runs keep exploring new ones.
settings.register_profile("ci", deadline=None, derandomize=True)
settings.load_profile("ci" if os.environ.get("CI") else "dev")


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption(
        "--all-boards",
        action="store_true",
        help="run every board test on the emulated Mega too, not only those marked mega",
    )


def pytest_generate_tests(metafunc: pytest.Metafunc) -> None:
    """A test taking ``board_id`` (``sim_board`` does) runs once per board of
    simfixtures.boards_for."""
    if "board_id" in metafunc.fixturenames:
        all_boards = bool(metafunc.config.getoption("all_boards"))
        metafunc.parametrize("board_id", boards_for(metafunc, all_boards))


#: How long a test's threads get to finish after it ends before they count as leaked (a
#: bound only: the check returns as soon as they have; a loaded machine may need seconds).
THREAD_GRACE = 10.0


@pytest.fixture(autouse=True)
def _no_thread_leaks() -> Iterator[None]:
    """Fail any test that leaves a thread running (a board not closed, a stuck I/O loop)."""
    before = set(threading.enumerate())
    yield
    deadline = time.monotonic() + THREAD_GRACE
    leaked: list[threading.Thread] = []
    while True:
        leaked = [t for t in threading.enumerate() if t not in before and t.is_alive()]
        if not leaked or time.monotonic() >= deadline:
            break
        time.sleep(0.02)
    if leaked:
        pytest.fail(f"test leaked threads: {sorted(t.name for t in leaked)}")
