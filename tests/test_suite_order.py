"""The order the suite's files are handed to the workers (tests/conftest.py): the files that
need a process without other threads first, then the costliest files, heaviest first, then
any other file with a stress test, then the rest as collected; a file's tests keep their
order."""

from __future__ import annotations

from pathlib import Path

import conftest

TESTS = Path(__file__).resolve().parent


class _Item:
    """What the ordering reads of a pytest item: its file and its ``stress`` marker."""

    def __init__(self, file: str, test: str, stress: bool = False) -> None:
        self.path = TESTS / file
        self.test = test
        self.stress = stress

    def get_closest_marker(self, name: str):
        return object() if name == "stress" and self.stress else None


def test_every_file_of_the_order_is_a_test_file_of_the_suite():
    """A renamed file would silently fall out of the order: each name is a file here, once."""
    names = conftest.FIRST + conftest.LONGEST_FIRST
    assert len(set(names)) == len(names)
    missing = [n for n in names if not (TESTS / n).is_file() or not n.startswith("test_")]
    assert missing == []


def test_listed_files_first_then_stress_files_then_the_rest_in_collection_order():
    alone = conftest.FIRST[0]
    first, second = conftest.LONGEST_FIRST[0], conftest.LONGEST_FIRST[1]
    items = [_Item("test_a.py", "a1"), _Item("test_b.py", "b1"),
             _Item(second, "s1"), _Item("test_b.py", "b2", stress=True),
             _Item(first, "f1"), _Item("test_a.py", "a2"), _Item(second, "s2"),
             _Item(alone, "p1"), _Item(first, "f2")]
    conftest.pytest_collection_modifyitems(None, items)
    assert [i.test for i in items] == ["p1", "f1", "f2", "s1", "s2", "b1", "b2", "a1", "a2"]


def test_the_forking_figure_tests_run_before_the_file_that_leaves_dask_threads():
    """test_plot_layout.py's fork tests skip in a process where another Python thread runs;
    test_sweep.py leaves Dask's offload thread in its worker: with --dist loadfile a worker
    runs files in the order they are handed out, so the first must come before the second."""
    order = conftest.FIRST + conftest.LONGEST_FIRST
    assert order.index("test_plot_layout.py") < order.index("test_sweep.py")
