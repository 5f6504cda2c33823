"""The `tracker` package imported in tests is the real one, not tests/tracker/ as a namespace package."""

from pathlib import Path


def test_tracker_package_is_the_real_one():
    import tracker
    from tracker import Box, get_preset  # noqa: F401 - the public API is importable from the top level

    assert Path(tracker.__file__).parent == Path(__file__).resolve().parents[2] / "tracker"
