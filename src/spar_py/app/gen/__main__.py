"""``python -m spar_py.app.gen``: :func:`spar_py.app.gen.main` (``spar gen``'s body)."""
import sys

from spar_py.app.gen import main

if __name__ == "__main__":  # pragma: no cover
    sys.exit(main(sys.argv[1:]))
