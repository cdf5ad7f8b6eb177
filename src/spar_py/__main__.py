"""``python -m spar_py``: the ``spar`` command, exactly as the console script runs it."""
from spar_py.startup.entry import main

main()
