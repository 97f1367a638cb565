"""``python -m couplekit`` runs the command line."""

import sys

try:
    from .cli import main
except KeyboardInterrupt:  # Ctrl-C while the modules load: nothing has started
    print("interrupted before the command started; nothing to save", file=sys.stderr)
    sys.exit(130)

sys.exit(main())
