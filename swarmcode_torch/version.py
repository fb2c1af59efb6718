"""The package version, in a leaf module that every layer may import (the package root imports
the application, so the application reads the version here, not from the root)."""

__version__ = "0.7.0"
