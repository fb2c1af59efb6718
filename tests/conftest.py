"""Test-wide settings. Ray, where a test starts it, listens on the loopback address only: with
this set before Ray is imported, Ray takes 127.0.0.1 as the node's address (instead of the
machine's network address), so no test talks to any other address of the machine."""

import os

os.environ.setdefault("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")
os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")


def pytest_sessionfinish(session, exitstatus):
    """The suite writes no run into the checkout's runs/ (a test that forgets its logdir would
    leave one there): a run directory made there during the session fails the session."""
    from pathlib import Path

    runs = Path(session.config.rootpath) / "runs"
    if not runs.is_dir():
        return
    start = getattr(session.config, "_swarmcode_start", None)
    made = [p.name for p in runs.iterdir() if start is not None and p.stat().st_mtime >= start]
    if made:
        session.exitstatus = 1
        print(f"\nthe tests wrote run directories into {runs}: {', '.join(made[:5])}")


def pytest_sessionstart(session):
    import time

    session.config._swarmcode_start = time.time()
