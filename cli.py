"""Run the dcts command line from a checkout: `python cli.py validate specs/minimal.yaml`."""

from dcts_spec.cli import main

if __name__ == "__main__":
    main()
