"""``python -m popup``: the same as the ``popup`` command (:mod:`popup.cli`)."""

import sys

from .cli import main

if __name__ == "__main__":
    sys.exit(main())
