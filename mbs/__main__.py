"""Command line: ``python -m mbs demo``."""

import argparse
import sys


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python -m mbs", description="Guaranteed simulation of multibody systems.")
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("demo", help="enclosures for the paper's pendulum and double pendulum, checked against sampling")
    args = parser.parse_args(argv)
    if args.command == "demo":
        from .demo import run

        return run()
    return 2


if __name__ == "__main__":
    sys.exit(main())
