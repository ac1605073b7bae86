"""``python -m mbs``: the command line lives in :mod:`mbs.app.cli`."""
import sys
from mbs.app.cli import main
if __name__ == "__main__":
    sys.exit(main())
