"""Test-wide settings. Ray, where a test starts it, listens on the loopback address only: with
this set before Ray is imported, Ray takes 127.0.0.1 as the node's address (instead of the
machine's network address), so no test talks to any other address of the machine."""

import os

os.environ.setdefault("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")
os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
