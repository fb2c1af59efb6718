"""`python -m swarmcode_torch ...`: the `swarmcode-torch` command line."""

from .app.cli import main

if __name__ == "__main__":
    main()
